import sys

from ipr_shapes.cli import main

sys.exit(main())
