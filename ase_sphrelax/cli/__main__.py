"""``python -m ase_sphrelax.cli`` is ``sphrelax``."""
import sys

from .main import main

sys.exit(main())
