"""``python -m sitl [flags]`` is ``koopguide sitl [flags]``."""

import sys

from sitl.cli import main

sys.exit(main(sys.argv[1:]))
