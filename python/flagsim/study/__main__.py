"""python -m flagsim.study: the same as `flagsim study` (an entry point: it may use the CLI)."""

import sys

from ..cli import main

sys.exit(main(["study", *sys.argv[1:]]))
