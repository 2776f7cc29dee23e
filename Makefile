# Convenience targets; each is one documented command.
.PHONY: sample-logs test bench

sample-logs:  ## regenerate the shipped sample logs (deterministic: same bytes every time)
	trackctl simulate demo --out sample_logs/demo.mcap --seed 0 --duration 20
	trackctl simulate bridgeloc --out sample_logs/bridgeloc.mcap --field lobby --tags 6 --duration 16 --infra-fps 2 --seed 0 --quiet

test:
	pytest -q

bench:
	python benchmarks/replay_throughput.py
