"""ndt-cli: marker-free registration of terrestrial laser scans with multi-slice 2D NDT.

One call registers two scans (file paths or (N,3) arrays, metres)::

    import ndt_cli
    result = ndt_cli.register("scan_00.laz", "scan_01.laz")
    result.T_target_source, result.status

The public names are loaded on first use, so importing the package (and every command's
``--help``) stays fast.

>>> import ndt_cli
>>> callable(ndt_cli.register)
True
"""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING, Any

__version__ = "0.2.0"

_PUBLIC = {
    "register": "ndt_cli.ndt.register",
    "register_prepared": "ndt_cli.ndt.register",
    "RegistrationResult": "ndt_cli.ndt.result",
    "Status": "ndt_cli.ndt.result",
    "PreparedScan": "ndt_cli.ndt.prepare",
    "load_and_prepare": "ndt_cli.ndt.prepare",
    "Config": "ndt_cli.config",
    "load_config": "ndt_cli.config",
    "read": "ndt_cli.io",
    "write": "ndt_cli.io",
    "NUMBA": "ndt_cli.ndt.backend",
    "NUMPY": "ndt_cli.ndt.backend",
}
_RENAMED = {"load_config": "load"}

__all__ = [
    "NUMBA",
    "NUMPY",
    "Config",
    "PreparedScan",
    "RegistrationResult",
    "Status",
    "__version__",
    "load_and_prepare",
    "load_config",
    "read",
    "register",
    "register_prepared",
    "write",
]

if TYPE_CHECKING:
    from ndt_cli.config import Config
    from ndt_cli.config import load as load_config
    from ndt_cli.io import read, write
    from ndt_cli.ndt.backend import NUMBA, NUMPY
    from ndt_cli.ndt.prepare import PreparedScan, load_and_prepare
    from ndt_cli.ndt.register import register, register_prepared
    from ndt_cli.ndt.result import RegistrationResult, Status


def __getattr__(name: str) -> Any:
    if name not in _PUBLIC:
        raise AttributeError(f"module 'ndt_cli' has no attribute {name!r}")
    value = getattr(import_module(_PUBLIC[name]), _RENAMED.get(name, name))
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(__all__)
