# Convenience targets; each is one documented command.
.PHONY: sample-logs test bench

sample-logs:  ## regenerate the shipped sample logs (deterministic: same bytes every time)
	trackctl simulate demo --out sample_logs/demo.mcap --seed 0 --duration 20
	trackctl simulate vm --out sample_logs/vm-office.mcap --field office --users 2 --nonusers 1 --duration 18 --seed 3 --frames --jpeg-quality 50

test:
	pytest -q

bench:
	python benchmarks/replay_throughput.py
