# Convenience targets; each is one documented command.
.PHONY: sample-logs test bench lock formats

sample-logs:  ## regenerate the shipped sample logs (deterministic: same bytes every time)
	trackctl simulate demo --out sample_logs/demo.mcap --seed 0 --duration 20
	trackctl simulate ev --out sample_logs/ev.mcap --people 400 --area 600 --duration 1200 --seed 0
	trackctl simulate bridgeloc --out sample_logs/bridgeloc.mcap --field lobby --tags 6 --duration 10 --infra-fps 1 --seed 0 --quiet
	trackctl simulate vm --out sample_logs/vm-office.mcap --field office --users 2 --nonusers 1 --duration 30 --seed 3 --frames --jpeg-quality 40
	trackctl simulate smirror --out sample_logs/smirror.mcap --paths 1 --size 320x240 --fps 2 --jpeg-quality 70 --duration 36 --seed 0 -q

test:
	pytest -q

bench:
	python benchmarks/replay_throughput.py

lock:  ## re-resolve every dependency (today's newest allowed by pyproject.toml) into constraints.txt
	rm -rf .venv-lock && python3 -m venv .venv-lock
	.venv-lock/bin/pip install --quiet --upgrade pip
	.venv-lock/bin/pip install --quiet -e '.[dev]'
	( echo "# Pinned versions CI and the README install with (pip install -c constraints.txt ...)."; \
	  echo "# Regenerate with 'make lock' (a fresh venv, today's resolver, then pip freeze); see docs/install.md."; \
	  .venv-lock/bin/pip freeze --exclude-editable ) > constraints.txt
	rm -rf .venv-lock

formats:  ## regenerate formats/*.json from the message classes (trackctl/logs/messages.py)
	python -c "from trackctl.logs.jsonmap import write_schemas; write_schemas('formats')"
