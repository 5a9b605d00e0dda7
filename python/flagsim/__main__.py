"""``python -m flagsim``: the flagsim command."""

import sys

from .cli import main

sys.exit(main())
