"""`python -m holoflow ...` is the `holoflow` command."""
import sys

from .cli import main

sys.exit(main())
