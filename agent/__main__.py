"""`python -m agent` is the same as the `sysid` command."""

import sys

from agent.cli import main

if __name__ == "__main__":  # a spawned worker process imports this module too
    sys.exit(main())
