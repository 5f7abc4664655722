"""``python -m soabench.cli``: the ``soabench`` console script."""

import sys

from soabench.cli.main import main

if __name__ == "__main__":
    sys.exit(main())
