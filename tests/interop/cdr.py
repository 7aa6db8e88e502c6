"""CDR helpers for the interop tests: serialize with the real ROS 2 libraries and find
the alignment padding, whose content CDR leaves unspecified (Fast CDR leaves stale
buffer bytes there; ros2-client writes zeros)."""
import struct

from rclpy.serialization import deserialize_message, serialize_message

from interop import idl

PRIMITIVE_SIZES = {
    "boolean": 1, "octet": 1, "byte": 1, "char": 1, "int8": 1, "uint8": 1,
    "int16": 2, "uint16": 2, "int32": 4, "uint32": 4, "float": 4,
    "int64": 8, "uint64": 8, "double": 8,
}


def is_idl(msg):
    return isinstance(msg, idl.IdlStruct)


def serialize(msg):
    """Bytes with the 4-byte encapsulation header, as a ROS 2 DataWriter sends them."""
    return bytes(msg.serialize()) if is_idl(msg) else bytes(serialize_message(msg))


def deserialize(data, like):
    return type(like).deserialize(data) if is_idl(like) else deserialize_message(data, type(like))


def _fields(msg):
    if is_idl(msg):
        import dataclasses
        out = {}
        for f in dataclasses.fields(msg):
            v = getattr(msg, f.name)
            if isinstance(v, float):
                out[f.name] = "double"
            elif isinstance(v, int):
                out[f.name] = "int32" if f.name == "sec" else "uint32"
            elif isinstance(v, str):
                out[f.name] = "string"
            elif isinstance(v, list):
                out[f.name] = "sequence<msg>"
            else:
                out[f.name] = "msg"
        return out
    return msg.get_fields_and_field_types()


def padding_mask(msg):
    """Set of byte offsets (in the serialized bytes, header included) that are alignment padding."""
    pad = set()
    pos = [0]  # offset from the start of the CDR body

    def align(n):
        while pos[0] % n:
            pad.add(4 + pos[0])
            pos[0] += 1

    def walk(value, typ):
        if typ.startswith("sequence<"):
            inner = typ[len("sequence<"):-1]
            align(4)
            pos[0] += 4
            for item in value:
                walk(item, inner)
        elif typ.endswith("]"):  # a fixed-size array, e.g. double[9]: no length
            inner = typ[:typ.index("[")]
            for item in value:
                walk(float(item) if inner == "double" else item, inner)
        elif typ.startswith("string"):
            align(4)
            pos[0] += 4 + len(value.encode("utf-8")) + 1
        elif typ in PRIMITIVE_SIZES:
            n = PRIMITIVE_SIZES[typ]
            align(n)
            pos[0] += n
        else:  # nested message
            for name, ftyp in _fields(value).items():
                walk(getattr(value, name), ftyp)

    walk(msg, "msg")
    return pad, 4 + pos[0]


def canonical(value):
    """A comparable form of a message: floats as their bit patterns (NaN, -0.0 exact)."""
    if isinstance(value, float):
        return ("f64", struct.pack("<d", value))
    if isinstance(value, (bytes, bytearray)):
        return ("bytes", bytes(value))
    if isinstance(value, (list, tuple)) or type(value).__name__ in ("array", "ndarray"):
        return [canonical(v) for v in value]
    if isinstance(value, (str, int, bool)) or value is None:
        return value
    names = _fields(value).keys()
    return (type(value).__name__, [(n, canonical(getattr(value, n))) for n in names])
