"""`woody replay` without the woody CLI: parse the subcommand's arguments and run it."""

import argparse
import sys

from woody_tools import replay

if __name__ == "__main__":
    parser = argparse.ArgumentParser(prog="woody replay")
    replay.add_arguments(parser)
    sys.exit(replay.run(parser.parse_args()))
