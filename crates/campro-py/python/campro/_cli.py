"""The ``campro`` console script: the whole command, run by the same Rust code as the binary."""

import signal
import sys

from . import _campro


def main() -> None:
    """Runs ``campro`` with this process's arguments and exits with its status."""
    # The command handles Ctrl-C itself (it removes half-written files); Python's handler
    # would only set a flag that the Rust code never reads.
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    _campro.main(["campro", *sys.argv[1:]])


if __name__ == "__main__":
    main()
