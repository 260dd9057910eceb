"""``python -m avrisk``: the ``avrisk`` command without its console script."""

from avrisk.cli import main

main()
