"""The command line, the top layer: ``koopguide <command>``; each sub-module registers its commands."""

from koopguide.cli.main import main

__all__ = ["main"]
