"""A simulated Crazyflie on a USB cable, as the fake pyusb backend shows it to the host.

Its identity and CRTP over USB follow the Crazyflie firmware (docs/protocol.md, "A Crazyflie on a USB
cable"): vendor 0x0483, product 0x5740, bcdDevice 0x0200, "Bitcraze AB" / "Crazyflie 2.x", a serial of
24 hex digits (the STM32's 96-bit id); vendor request 0x01 wValue 1 wIndex 1/0 sends its CRTP to USB
or back to the radio; a bulk OUT is one CRTP packet for the STM, a bulk IN one packet from it. The
packets go straight to the simulated STM through the medium (``usb_send``/``usb_receive``): no nRF,
no safelink, no radio faults.
"""
from __future__ import annotations

import threading
from collections import deque
from typing import Deque, Optional

from crazyflie_driver.radio.usb_crazyflie import (
    CRAZYFLIE_MANUFACTURER,
    CRAZYFLIE_PRODUCT_ID,
    CRAZYFLIE_VENDOR_ID,
    SET_CRTP_TO_USB,
)
from crazyflie_driver.sim.air.dongle import VENDOR_REQUEST_LOG
from crazyflie_driver.sim.air.usb_descriptors import DESC_DEVICE, Descriptor, DongleModel

CRAZYFLIE_BCD_DEVICE = 0x0200
CRAZYFLIE_PRODUCT = "Crazyflie 2.x"
SERIAL_INDEX = 3
#: Its interface as the descriptor builders of the dongles take it: vendor class, subclass 0, bulk
#: endpoints 0x81/0x01 of 64 bytes.
CABLE_MODEL = DongleModel("Crazyflie", CRAZYFLIE_BCD_DEVICE, CRAZYFLIE_MANUFACTURER, CRAZYFLIE_PRODUCT,
                          SERIAL_INDEX, 0x00, 0, 24)


class FakeCableCrazyflie:
    """The USB side of simulated Crazyflie ``usb://index`` (the attributes a fake handle checks)."""

    def __init__(self, ident: int, index: int) -> None:
        self.ident = ident                 # the backend's device id
        self.index = index                 # N of usb://N, the medium's cable number
        self.model = CABLE_MODEL
        self.serial = "%024X" % (0x00C0FFEE0000000000000000 + index)
        self.lock = threading.Lock()
        self.unplugged = False
        self.generation = 0
        self.configuration = 1
        self.claimed_by: Optional[object] = None
        self.reply: Optional[bytes] = None
        self.in_bootloader = False
        self.bootloader_requested = False
        self.crtp_to_usb = False
        self.control_transfers = 0
        self.vendor_requests: Deque[tuple] = deque(maxlen=VENDOR_REQUEST_LOG)   # as a dongle's
        self.bulk_out = 0
        self.bulk_in = 0

    def __repr__(self) -> str:
        return "<FakeCableCrazyflie usb://%d serial %s>" % (self.index, self.serial)


def device_descriptor(cf: FakeCableCrazyflie) -> Descriptor:
    return Descriptor(
        bLength=18, bDescriptorType=DESC_DEVICE, bcdUSB=0x0200, bDeviceClass=0, bDeviceSubClass=0,
        bDeviceProtocol=0, bMaxPacketSize0=64, idVendor=CRAZYFLIE_VENDOR_ID, idProduct=CRAZYFLIE_PRODUCT_ID,
        bcdDevice=CRAZYFLIE_BCD_DEVICE, iManufacturer=1, iProduct=2, iSerialNumber=SERIAL_INDEX,
        bNumConfigurations=1, bus=2, address=cf.index + 2, port_number=cf.index + 1, port_numbers=(cf.index + 1,),
        speed=2)


def device_descriptor_bytes() -> bytes:
    return bytes([18, 1, 0x00, 0x02, 0, 0, 0, 64,
                  CRAZYFLIE_VENDOR_ID & 0xFF, CRAZYFLIE_VENDOR_ID >> 8,
                  CRAZYFLIE_PRODUCT_ID & 0xFF, CRAZYFLIE_PRODUCT_ID >> 8,
                  CRAZYFLIE_BCD_DEVICE & 0xFF, CRAZYFLIE_BCD_DEVICE >> 8, 1, 2, SERIAL_INDEX, 1])


def string_descriptor(cf: FakeCableCrazyflie, index: int) -> Optional[bytes]:
    if index == 0:
        return bytes([4, 3, 0x09, 0x04])
    text = {1: CRAZYFLIE_MANUFACTURER, 2: CRAZYFLIE_PRODUCT, SERIAL_INDEX: cf.serial}.get(index)
    if text is None:
        return None
    raw = text.encode("utf-16-le")
    return bytes([len(raw) + 2, 3]) + raw


def vendor_out(cf: FakeCableCrazyflie, request: int, value: int, index: int) -> bool:
    """A vendor request to the Crazyflie; False when it does not know it (the host sees a STALL)."""
    if request == SET_CRTP_TO_USB and value == 1:
        cf.crtp_to_usb = index != 0
        return True
    return False
