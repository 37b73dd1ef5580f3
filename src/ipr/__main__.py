import sys

from ipr.cli import main

sys.exit(main())
