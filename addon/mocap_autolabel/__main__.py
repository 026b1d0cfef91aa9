"""``python -m mocap_autolabel ...``: the command line."""

import sys

from .cli import main

sys.exit(main())
