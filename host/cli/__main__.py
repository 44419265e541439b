"""``python -m accelnav.cli``: the accelnav command."""

import sys

from accelnav.cli import main

sys.exit(main())
