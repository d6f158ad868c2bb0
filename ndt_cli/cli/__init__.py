"""Command-line entry points, one Typer app per command. They parse options and call the library.

Exit codes: 0 success, 1 registration failed or not trustworthy, 2 bad input or config, 130
stopped by Ctrl-C. Heavy modules are imported inside the commands so that ``--help`` stays fast.
"""

import os

# One BLAS thread: a command's heavy work runs in Numba's threads, which BLAS threads would spin
# against, and a chain's process can fork its workers only while it has a single thread.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from ndt_cli.cli.analyze import analyze_app
from ndt_cli.cli.chain import chain_app
from ndt_cli.cli.evaluate import eval_app
from ndt_cli.cli.export import export_app
from ndt_cli.cli.register import register_app
from ndt_cli.cli.watch import watch_app

__all__ = ["analyze_app", "chain_app", "eval_app", "export_app", "register_app", "watch_app"]
