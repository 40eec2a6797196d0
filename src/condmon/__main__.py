"""``python -m condmon``: the same command line as ``condmon`` (for an
environment whose scripts folder is not on the PATH)."""

from condmon.cli.main import run

if __name__ == "__main__":
    run()
