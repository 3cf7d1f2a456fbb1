"""``python -m campro``: the ``campro`` command."""

from ._cli import main

main()
