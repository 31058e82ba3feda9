"""``python -m lumbar.discovery --config CONFIG --measured FILE.csv --out DIR`` (:mod:`lumbar.discovery.cli`)."""
import sys

from .cli import main

if __name__ == "__main__":
    sys.exit(main())
