"""Command-line pieces shared by the benchmark scripts."""

from __future__ import annotations

import argparse

from hierloco.envs import get_robot


def positive_int(text: str) -> int:
    """An ``argparse`` type: a positive integer."""
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {text}")
    return value


def check_robot_names(parser: argparse.ArgumentParser, names) -> None:
    """Exits through ``parser.error`` on the first name that is not a registered robot."""
    for name in names:
        try:
            get_robot(name)
        except ValueError as error:
            parser.error(str(error))
