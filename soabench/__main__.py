"""``python -m soabench``: the same program as the ``soabench`` console script (docs/user-guide/install.md)."""

import sys

from soabench.cli.main import main

if __name__ == "__main__":
    sys.exit(main())
