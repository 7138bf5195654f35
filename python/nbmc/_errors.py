# SPDX-License-Identifier: MIT
"""Exceptions: one class per nbmc status code, all derived from :class:`Error`."""
from __future__ import annotations

from typing import Dict, Type

from . import _capi as C


class Error(Exception):
    """A failed nbmc call.

    ``status`` is the library's status code (``nbmc.ERROR_*``), ``status_name``
    its name (``nbmc_status_string``) and ``message`` the library's own message
    (``nbmc_context_last_error`` / ``nbmc_last_error``), which names the file,
    the parameter or the first bad particle.
    """

    status: int
    message: str

    def __init__(self, status: int, message: str = "") -> None:
        self.status = int(status)
        self.status_name = C.text(C.lib.nbmc_status_string(self.status))
        self.message = message or self.status_name
        super().__init__(self.message)
        self.args = (self.status, self.message)

    def __str__(self) -> str:
        if self.message == self.status_name:
            return self.message
        return f"{self.message} [{self.status_name}]"

    def __reduce__(self):  # pickles as the same class with the same fields
        return (type(self), (self.status, self.message))


class InvalidArgument(Error, ValueError):
    """NBMC_ERROR_INVALID_ARGUMENT: a bad value or a call that is not allowed now."""


class InvalidParticles(Error, ValueError):
    """NBMC_ERROR_INVALID_PARTICLES: a coordinate is NaN, infinite or beyond 1e15."""


class NoParticles(Error, ValueError):
    """NBMC_ERROR_NO_PARTICLES: zero particles, none uploaded, or no reconstruction yet."""


class InvalidParameter(Error, ValueError):
    """NBMC_ERROR_INVALID_PARAMETER: a reconstruction parameter is out of range."""


class DomainTooLarge(Error, ValueError):
    """NBMC_ERROR_DOMAIN_TOO_LARGE: grid or mesh indices would overflow."""


class OutOfMemory(Error, MemoryError):
    """NBMC_ERROR_OUT_OF_MEMORY: a host or device allocation failed."""


class BackendUnavailable(Error, RuntimeError):
    """NBMC_ERROR_BACKEND_UNAVAILABLE: backend not compiled in, no device, or a
    device-memory call on a context that does not use CUDA."""


class FileError(Error, OSError):
    """NBMC_ERROR_IO: a file could not be opened, read or written."""

    def __str__(self) -> str:  # OSError's own __str__ would show "[Errno 8] ..."
        return Error.__str__(self)


class InternalError(Error, RuntimeError):
    """NBMC_ERROR_INTERNAL: a bug in nbmc; please report it with the message."""


class MemoryBudgetExceeded(Error, MemoryError):
    """NBMC_ERROR_MEMORY_BUDGET: the estimated need exceeds the memory budget."""


class Cancelled(Error):
    """NBMC_ERROR_CANCELLED: the progress callback asked to stop."""


class FormatError(Error, ValueError):
    """NBMC_ERROR_FORMAT: a file is malformed or of an unsupported kind."""


_BY_STATUS: Dict[int, Type[Error]] = {
    C.ERROR_INVALID_ARGUMENT: InvalidArgument,
    C.ERROR_INVALID_PARTICLES: InvalidParticles,
    C.ERROR_NO_PARTICLES: NoParticles,
    C.ERROR_INVALID_PARAMETER: InvalidParameter,
    C.ERROR_DOMAIN_TOO_LARGE: DomainTooLarge,
    C.ERROR_OUT_OF_MEMORY: OutOfMemory,
    C.ERROR_BACKEND_UNAVAILABLE: BackendUnavailable,
    C.ERROR_IO: FileError,
    C.ERROR_INTERNAL: InternalError,
    C.ERROR_MEMORY_BUDGET: MemoryBudgetExceeded,
    C.ERROR_CANCELLED: Cancelled,
    C.ERROR_FORMAT: FormatError,
}


def error_for(status: int, message: str) -> Error:
    """The exception for a status code (plain :class:`Error` for unknown codes)."""
    return _BY_STATUS.get(status, Error)(status, message)
