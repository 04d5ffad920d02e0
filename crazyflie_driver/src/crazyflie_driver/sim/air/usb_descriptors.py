"""What a fake Crazyradio tells the USB host about itself: its model and its descriptors.

The models (Crazyradio PA with firmware 0.53 or the 99.55 development image, Crazyradio 2.0 with
firmware 5.4 or, without inline mode, 5.0) and their descriptors as libusb reports them; sources
in docs/simulation.md, "The fake Crazyradio".
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

from crazyflie_driver.radio.crazyradio import VENDOR_ID

DESC_DEVICE, DESC_CONFIG, DESC_STRING = 1, 2, 3


@dataclass
class DongleModel:
    """What tells one Crazyradio model from another on the bus."""

    name: str
    bcd_device: int
    manufacturer: str
    product: str
    serial_index: int
    interface_subclass: int
    endpoint_interval: int
    serial_digits: int
    #: Highest SET_INLINE_MODE value the firmware accepts: 0 none (PA, 2.0 before 5.1), 1 inline
    #: mode (5.1), 2 inline mode with RSSI (5.3 on).
    inline_modes: int = 0

    @property
    def is_crazyradio_2(self) -> bool:
        return self.product == "Crazyradio 2.0"

    @property
    def splits_long_no_ack(self) -> bool:
        """An unacked OUT of more than 32 bytes goes out as two radio packets of half its length: the
        PA's "99.55" image, and every Crazyradio 2.0 (its legacy path since release 1.0)."""
        return self.bcd_device == 0x9955 or self.is_crazyradio_2


PA_053 = DongleModel("PA", 0x0053, "Bitcraze", "Crazyradio PA USB Dongle", 0x1D, 0xFF, 6, 10)
#: The PA with the development firmware "99.55" swarm setups flash: an unacked OUT of more than 32
#: bytes goes out as two radio packets of half its length each.
PA_9955 = DongleModel("PA-99.55", 0x9955, "Bitcraze", "Crazyradio PA USB Dongle", 0x1D, 0xFF, 6, 10)
CRAZYRADIO_2_54 = DongleModel("2.0", 0x0504, "Bitcraze AB", "Crazyradio 2.0", 3, 0x00, 0, 16, 2)
#: The first Crazyradio 2.0 release with bcdDevice = app version: no inline mode (0x23 STALLs).
CRAZYRADIO_2_50 = DongleModel("2.0-5.0", 0x0500, "Bitcraze AB", "Crazyradio 2.0", 3, 0x00, 0, 16, 0)
MODELS = {"PA": PA_053, "pa": PA_053, "PA-99.55": PA_9955, "pa-99.55": PA_9955, "2.0": CRAZYRADIO_2_54,
          "2": CRAZYRADIO_2_54, "2.0-5.0": CRAZYRADIO_2_50}
PA_MODELS = (PA_053, PA_9955)


class Descriptor:
    """A descriptor object with the attributes pyusb copies."""

    def __init__(self, **fields):
        self.__dict__.update(fields)


def device_descriptor(model: DongleModel, ident: int, product_id: int) -> Descriptor:
    return Descriptor(
        bLength=18, bDescriptorType=DESC_DEVICE, bcdUSB=0x0200,
        bDeviceClass=0, bDeviceSubClass=0, bDeviceProtocol=0, bMaxPacketSize0=64,
        idVendor=VENDOR_ID, idProduct=product_id, bcdDevice=model.bcd_device,
        iManufacturer=1, iProduct=2, iSerialNumber=model.serial_index, bNumConfigurations=1,
        bus=1, address=ident + 2, port_number=ident + 1, port_numbers=(ident + 1,),
        speed=2)  # libusb speed 2 = full speed


def configuration_descriptor(config: int) -> Descriptor:
    if config != 0:
        raise IndexError("configuration index %d out of range" % config)
    return Descriptor(
        bLength=9, bDescriptorType=DESC_CONFIG, wTotalLength=32, bNumInterfaces=1,
        bConfigurationValue=1, iConfiguration=0, bmAttributes=0x80, bMaxPower=50,
        extra_descriptors=[])


def interface_descriptor(model: DongleModel, intf: int, alt: int, config: int) -> Descriptor:
    if config != 0 or intf != 0 or alt != 0:
        raise IndexError("interface %d alt %d (configuration %d) out of range" % (intf, alt, config))
    return Descriptor(
        bLength=9, bDescriptorType=4, bInterfaceNumber=0, bAlternateSetting=0,
        bNumEndpoints=2, bInterfaceClass=0xFF, bInterfaceSubClass=model.interface_subclass,
        bInterfaceProtocol=0, iInterface=0, extra_descriptors=[])


def endpoint_descriptor(model: DongleModel, ep: int, intf: int, alt: int, config: int) -> Descriptor:
    if config != 0 or intf != 0 or alt != 0 or ep not in (0, 1):
        raise IndexError("endpoint %d out of range" % ep)
    return Descriptor(
        bLength=7, bDescriptorType=5, bEndpointAddress=0x81 if ep == 0 else 0x01,
        bmAttributes=0x02, wMaxPacketSize=64, bInterval=model.endpoint_interval,
        bRefresh=0, bSynchAddress=0, extra_descriptors=[])


def device_descriptor_bytes(model: DongleModel, product_id: int) -> bytes:
    """The device descriptor as the GET_DESCRIPTOR data stage carries it."""
    return bytes([18, 1, 0x00, 0x02, 0, 0, 0, 64,
                  VENDOR_ID & 0xFF, VENDOR_ID >> 8, product_id & 0xFF, product_id >> 8,
                  model.bcd_device & 0xFF, model.bcd_device >> 8, 1, 2, model.serial_index, 1])


def config_descriptor_bytes(model: DongleModel) -> bytes:
    """Configuration, interface and both bulk endpoint descriptors, as one data stage."""
    interval = model.endpoint_interval
    return bytes([9, 2, 32, 0, 1, 1, 0, 0x80, 50,
                  9, 4, 0, 0, 2, 0xFF, model.interface_subclass, 0, 0,
                  7, 5, 0x81, 0x02, 64, 0, interval,
                  7, 5, 0x01, 0x02, 64, 0, interval])


def string_descriptor(model: DongleModel, serial: str, index: int) -> Optional[bytes]:
    """String descriptor ``index`` (0: the LANGID list), None when the dongle has none."""
    if index == 0:
        return bytes([4, 3, 0x09, 0x04])  # one LANGID: 0x0409 (English, US)
    text = {1: model.manufacturer, 2: model.product, model.serial_index: serial}.get(index)
    if text is None:
        return None
    raw = text.encode("utf-16-le")
    return bytes([len(raw) + 2, 3]) + raw
