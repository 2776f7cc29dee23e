"""``python -m trackctl``."""

from trackctl.cli.main import main

main()
