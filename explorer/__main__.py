"""``python -m explorer`` is the ``pushbroom`` command line."""

import sys

from explorer.cli import main

sys.exit(main())
