"""What the network readers of tests/tests/python_zenoh.rs share."""

import sys
import time


def first_run(net, deadline):
    """The info of the first run that answers `formation/*/info` before `deadline`
    (`time.monotonic()`); exits the reader when none does."""
    while time.monotonic() < deadline:
        runs = net.runs(timeout=1.0)
        if runs:
            return runs[0]
    sys.exit("no run answered formation/*/info")
