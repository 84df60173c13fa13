"""``python -m explorer`` is the ``pushbroom`` command line."""

from explorer.cli import run

run()
