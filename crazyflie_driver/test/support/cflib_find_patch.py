"""Make Bitcraze's cflib fly the simulated world: ``usb.core.find`` redirected to a fake Crazyradio.

cflib passes its own pyusb backend to ``usb.core.find``, so injecting a backend is not enough for it;
only the cflib comparison tests need this, so it lives in the test support, not in the simulator.
"""
from __future__ import annotations

from typing import Callable, Optional

import usb.backend
import usb.core

_original_find: Optional[Callable] = None
_original_libusb_package = None


def install_find_patch(backend: usb.backend.IBackend) -> Callable[[], None]:
    """Wrap ``usb.core.find`` so every call uses ``backend`` (cflib always passes its own backend=).

    Also replaces ``libusb_package.get_libusb1_backend`` when that module is installed. Returns the
    matching uninstall function (same as ``uninstall_find_patch``). Installing twice replaces the
    backend of the first patch.
    """
    global _original_find, _original_libusb_package
    if _original_find is None:
        _original_find = usb.core.find
    original = _original_find

    def find(*args, **kwargs):
        kwargs["backend"] = backend
        return original(*args, **kwargs)

    find.__doc__ = original.__doc__
    find.fake_backend = backend  # type: ignore[attr-defined]
    usb.core.find = find
    try:
        import libusb_package  # type: ignore
    except ImportError:
        pass
    else:
        if _original_libusb_package is None:
            _original_libusb_package = libusb_package.get_libusb1_backend
        libusb_package.get_libusb1_backend = lambda *a, **k: backend
    return uninstall_find_patch


def uninstall_find_patch() -> None:
    """Restore ``usb.core.find`` (and libusb_package) as they were before ``install_find_patch``."""
    global _original_find, _original_libusb_package
    if _original_find is not None:
        usb.core.find = _original_find
        _original_find = None
    if _original_libusb_package is not None:
        import libusb_package  # type: ignore
        libusb_package.get_libusb1_backend = _original_libusb_package
        _original_libusb_package = None
