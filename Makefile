# Convenience targets; each is one documented command.
.PHONY: sample-logs test bench

sample-logs:  ## regenerate the shipped sample logs (deterministic: same bytes every time)
	trackctl simulate demo --out sample_logs/demo.mcap --seed 0 --duration 20
	trackctl simulate smirror --out sample_logs/smirror.mcap --paths 1 --size 320x240 --fps 2 --jpeg-quality 70 --duration 36 --seed 0 -q

test:
	pytest -q

bench:
	python benchmarks/replay_throughput.py
