"""Fixed little-endian binary records with named fields (the serial protocol's, host/protocol.py)."""

from __future__ import annotations

import struct


class Layout:
    """A record, field by field as (name, struct code): ``pack``/``unpack``/``unpack_from``/``size`` as
    struct.Struct's, and ``offsets``, each field's place (host.protocol_c renders them for the firmware)."""

    def __init__(self, *fields: tuple[str, str], then: str = ""):
        self.fields = fields
        self.then = then  # what follows the fixed part, if anything
        self.struct = struct.Struct("<" + "".join(code for _, code in fields))
        self.size = self.struct.size
        self.pack, self.unpack, self.unpack_from = self.struct.pack, self.struct.unpack, self.struct.unpack_from
        self.offsets = {name: struct.calcsize("<" + "".join(code for _, code in fields[:i]))
                        for i, (name, _) in enumerate(fields)}
