"""``python -m tpnet_gpu.cli``: the ``tpnet`` command."""

import sys

from tpnet_gpu.cli import main

if __name__ == "__main__":  # importing it (the packaging test imports every module) runs nothing
    sys.exit(main())
