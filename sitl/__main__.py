"""``python -m sitl [flags]`` is ``koopguide sitl [flags]``."""

import sys

from koopguide.cli import main

sys.exit(main(["sitl", *sys.argv[1:]]))
