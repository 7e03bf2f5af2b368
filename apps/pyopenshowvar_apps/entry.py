"""The ``kvp`` console script: the command line, or one line naming the extra to install.

The script is installed with the package whatever extras were chosen, so a client-only install
(``pip install pyopenshowvar``) still has a ``kvp`` that must not end in a traceback. This
module imports nothing beyond the standard library and :mod:`pyopenshowvar.extras` before it
knows the command line's own dependencies are there.
"""

from __future__ import annotations

import sys

from pyopenshowvar.extras import explain

#: Exit status when an optional extra is missing (the usage-error status of ``kvp``).
EXIT_MISSING_EXTRA = 2


def main() -> None:
    """Run ``kvp``; a missing extra is one ``kvp:`` line on stderr and exit status 2."""
    try:
        from pyopenshowvar_apps.cli import main as cli_main
    except ModuleNotFoundError as exc:
        error = explain(exc, "the kvp command line")
        if error is None:
            raise
        print(f"kvp: {error}", file=sys.stderr)
        sys.exit(EXIT_MISSING_EXTRA)
    cli_main()
