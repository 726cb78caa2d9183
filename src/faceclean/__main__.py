import sys

from faceclean.cli import main

sys.exit(main())
