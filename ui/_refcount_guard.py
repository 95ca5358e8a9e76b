"""Guard against PySide6 builds that hand out ``None`` and ``True`` without a reference.

PySide6 6.12.0 (abi3 wheels) on CPython 3.11 returns ``None`` from every void method and
``True`` from ``Signal.emit()`` without taking a reference, as if they were immortal (they
are only from CPython 3.12 on). Each call then steals a reference, and after some thousand
calls Python aborts with ``deallocating None`` or ``deallocating True or False``.

:func:`protect_singletons` detects the fault with a few probe calls and, only then, raises
the reference counts of ``None``, ``True`` and ``False`` by a margin no session can use up.
These objects are never freed in a healthy process, so the extra count changes nothing else.
On an unaffected PySide6 or CPython >= 3.12 it does nothing.
"""

from __future__ import annotations

import ctypes
import sys

#: Added to each singleton's count: 2**40 stolen references (years of calls) fit in it.
HEADROOM = 1 << 40
_SINGLETONS = (None, True, False)
_done = False


def _counts() -> list[int]:
    return [sys.getrefcount(obj) for obj in _SINGLETONS]


def protect_singletons() -> bool:
    """Detect the fault and compensate it; True when a compensation was made."""
    global _done
    if _done or sys.version_info >= (3, 12):
        return False
    from PySide6.QtCore import QObject, Signal

    class _Probe(QObject):
        ping = Signal()

    probe = _Probe()
    before = _counts()
    for _ in range(16):
        probe.setObjectName("probe")
        probe.ping.emit()
    after = _counts()
    _done = True
    if all(a >= b for a, b in zip(after, before, strict=True)):
        return False
    for obj in _SINGLETONS:
        cell = ctypes.c_ssize_t.from_address(id(obj))
        if cell.value == sys.getrefcount(obj) - 1:  # the count is the object's first field
            cell.value += HEADROOM
    return True
