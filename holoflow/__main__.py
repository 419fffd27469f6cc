"""`python -m holoflow ...` is the `holoflow` command."""

import sys

from .commands import main

sys.exit(main())
