import sys

from videotrack.cli import main

sys.exit(main())
