"""The probe sensor's driver a rig's `probe` section names: the FSE103's or the load cell's."""

from __future__ import annotations

from hoh_cosim.hardware.config import ProbeConfig
from hoh_cosim.hardware.serial_source import SerialSource
from hoh_cosim.hardware.streams import Mailbox

__all__ = ["probe_port"]


def probe_port(
    config: ProbeConfig, *, reconnect: bool = True, mailbox: Mailbox | None = None
) -> SerialSource:
    """The driver of `config.sensor` on `config.device` (not started), publishing into `mailbox`
    (None: a mailbox of its own)."""
    if config.sensor == "loadcell":
        from hoh_cosim.hardware.loadcell import LoadCellPort

        return LoadCellPort(
            config.device, baudrate=config.baudrate, reconnect=reconnect, mailbox=mailbox
        )
    from hoh_cosim.hardware.fse103 import FSE103Port

    return FSE103Port(
        config.device,
        baudrate=config.baudrate,
        framing=config.framing,
        byte_order=config.byte_order,
        reconnect=reconnect,
        mailbox=mailbox,
    )
