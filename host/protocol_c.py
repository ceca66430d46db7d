"""The protocol's numbers in C: ``proto_defs.h``, rendered from :mod:`host.protocol` when a firmware is
rendered, so that the device and the host read one description (as nanopb renders both sides from one
schema). No C file writes a message type, an error code, a limit or a record's offset of its own."""

from __future__ import annotations

from host import protocol as P

# the numbers the firmware uses, by their C name (PROTO_ + name)
NUMBERS = {"VERSION": P.PROTOCOL_VERSION, "MAX_PAYLOAD": P.MAX_PAYLOAD, "CRC_SIZE": P.CRC_SIZE,
           "MAX_BODY": P.MAX_BODY, "MAX_ENCODED": P.MAX_ENCODED, "CAL_DATA_MAX": P.CAL_DATA_MAX,
           "CAL_READ_MAX": P.CAL_READ_MAX, "BENCH_MAX": P.BENCH_MAX, "HASH_SIZE": P.HASH_SIZE,
           "SENSOR_ID_SIZE": P.SENSOR_ID_SIZE, "FW_VERSION_SIZE": P.FW_VERSION_SIZE}
_TYPES = {"B": "u8", "H": "u16", "I": "u32", "Q": "u64", "i": "i32"}


def _field_text(name: str, code: str) -> str:
    return f"{name}:{_TYPES[code]}" if code in _TYPES else f"{name}[{code[:-1]}]"


def _groups():
    """The header's groups in order: (comment, "define" or "enum", number format, [(C name, value)])."""
    yield "", "define", "{}", [(f"PROTO_{name}", value) for name, value in NUMBERS.items()]
    yield "INFO's precision code", "define", "{}", [(f"PROTO_PRECISION_{name.upper()}", code)
                                                    for code, name in enumerate(P.PRECISIONS)]
    yield "a reply's type: its request's | PROTO_REPLY", "define", "0x{:02X}", [("PROTO_REPLY", P.REPLY)]
    yield "message types", "enum", "0x{:02X}", [(f"PROTO_MSG_{t.name}", int(t)) for t in P.MsgType]
    yield "error codes of the ERROR reply", "enum", "{}", [(f"PROTO_{e.name}", int(e)) for e in P.ErrorCode]
    for record, layout in P.LAYOUTS.items():
        text = " ".join(_field_text(name, code) for name, code in layout.fields)
        yield (f"{record}: {text}{', then ' + layout.then if layout.then else ''}", "define", "{}",
               [(f"PROTO_{record}_{field.upper()}", at) for field, at in layout.offsets.items()]
               + [(f"PROTO_{record}_SIZE", layout.size)])


def defines() -> dict[str, int]:
    """Every constant of proto_defs.h by its C name; ValueError when two would share a name."""
    pairs = [pair for *_, group in _groups() for pair in group]
    names = [name for name, _ in pairs]
    twice = sorted({name for name in names if names.count(name) > 1})
    if twice:
        raise ValueError(f"proto_defs.h: {', '.join(twice)} would be defined twice")
    return dict(pairs)


def render_proto_defs() -> str:
    """The text of ``proto_defs.h``."""
    defines()  # every name once
    lines = ["/* proto_defs.h: the numbers of docs/protocol.md, rendered from host/protocol.py (host.protocol_c).",
             " * Do not edit: change host/protocol.py, and the firmware and the host change together. */",
             "#ifndef PROTO_DEFS_H", "#define PROTO_DEFS_H"]
    for comment, form, number, group in _groups():
        lines += [""] + ([f"/* {comment} */"] if comment else [])
        if form == "enum":
            lines += ["enum {"] + [f"    {name} = {number.format(value)}," for name, value in group] + ["};"]
        else:
            lines += [f"#define {name} {number.format(value)}u" for name, value in group]
    return "\n".join(lines + ["", "#endif /* PROTO_DEFS_H */", ""])
