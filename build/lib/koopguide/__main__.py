import sys

from koopguide.cli import main

sys.exit(main())
