import sys

from windowshop.cli import main

sys.exit(main())
