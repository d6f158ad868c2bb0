"""One exception family for everything the user can cause or fix.

The CLI turns an :class:`NdtError` into a one-line message and the exit code
stored on its class; anything else is a bug and keeps its traceback.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

EXIT_OK = 0
EXIT_REGISTRATION = 1
EXIT_INPUT = 2
EXIT_INTERRUPTED = 130


def read_user_text(path: str | Path, what: str, error: type[NdtError] | None = None) -> str:
    """UTF-8 text of a file the user named; a missing or unreadable file raises ``error``
    (default :class:`InputError`) with a one-line message naming the file and ``what`` it is."""
    p = Path(path)
    cls = error or InputError
    try:
        return p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise cls(f"{what} file not found", p) from None
    except (OSError, UnicodeDecodeError) as exc:
        reason = getattr(exc, "strerror", None) or " ".join(str(exc).split())
        raise cls(f"cannot read {what} ({reason})", p) from None


LIBE57_REPORT = "**** Got an e57 exception"
"""Start of the debug report libE57 appends to the text of its exceptions (several lines of
file names, line numbers and internal state): never shown."""


def one_line(exc: BaseException, limit: int = 160) -> str:
    """An exception's text on one line (without libE57's debug report), at most ``limit``
    characters."""
    text = " ".join(str(exc).split(LIBE57_REPORT, 1)[0].split()) or type(exc).__name__
    return text if len(text) <= limit else text[: limit - 3] + "..."


def caused_by_interrupt(exc: BaseException | None) -> bool:
    """Whether Ctrl-C caused ``exc``: a KeyboardInterrupt, or an error raised while one was
    handled (a compiled module interrupted in its import fails with ImportError)."""
    seen: set[int] = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return True
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return False


class NdtError(Exception):
    """Base of all user-facing errors; ``exit_code`` is what the CLI returns."""

    exit_code: int = EXIT_INPUT

    def __init__(self, message: str, path: str | Path | None = None) -> None:
        self.path = None if path is None else Path(path)
        self.message = message
        super().__init__(f"{self.path}: {message}" if self.path is not None else message)


class InputError(NdtError):
    """A point file is missing, unreadable, of unknown type or holds no usable points."""

    exit_code = EXIT_INPUT


class ConfigError(NdtError):
    """The YAML configuration (or a CLI option) is invalid: unknown key, wrong type, bad value."""

    exit_code = EXIT_INPUT


class OutputError(NdtError):
    """An output file or folder cannot be written."""

    exit_code = EXIT_INPUT


class UserInterruptError(NdtError):
    """Stopped by Ctrl-C / SIGINT; what finished is kept (``ndt-chain --resume`` continues)."""

    exit_code = EXIT_INTERRUPTED


@contextmanager
def interrupt_as(message: Callable[[], str]) -> Iterator[None]:
    """Ctrl-C inside (:func:`caused_by_interrupt`) raised as one :class:`UserInterruptError`
    of ``message()``, said when it happens; any other error passes unchanged."""
    try:
        yield
    except BaseException as exc:
        if not caused_by_interrupt(exc):
            raise
        raise UserInterruptError(message()) from None
