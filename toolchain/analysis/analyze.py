#!/usr/bin/python3
"""Entry point of `toolchain/nao analyze` (usage: toolchain/nao analyze --help)."""

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from nao_analysis.cli import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
