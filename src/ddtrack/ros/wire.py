"""ROS 2 messages as DDS carries them: Cyclone DDS types generated from ``rosbags``' definitions (docs/ros.md).

A message is defined once, by the ROS 2 Jazzy type store that ``ddtrack.ros.messages`` builds its messages from:
the DDS type of ``geometry_msgs/msg/Twist`` is generated from that store's field definitions, named as ROS 2's
middlewares name it (``geometry_msgs::msg::dds_::Twist_``), and final, so it is written as plain CDR (XCDR1,
encapsulation ``CDR_LE``): the very bytes a ROS 2 bag stores for the message. Conversion goes both ways, between a
``rosbags`` message instance and the generated type's instance, for any message in the store.

``cyclonedds`` is optional (``pip install 'ddtrack[ros]'``): it is imported only here, inside the functions that
need it, so ``import ddtrack.ros`` works without it.
"""

from __future__ import annotations

import difflib
from functools import cache
from typing import Any

import numpy as np
from rosbags.interfaces import Nodetype

from ..errors import ConfigError
from .messages import typestore

INSTALL = "pip install 'ddtrack[ros]'"

#: the kinds of a field in rosbags' descriptions: a base type, a message, an array (else a sequence)
_BASE, _NAME, _ARRAY = Nodetype.BASE, Nodetype.NAME, Nodetype.ARRAY

#: the numpy element type rosbags gives an array or a sequence of each base type (a ``byte`` is signed in rosbags,
#: a ``char`` unsigned: one byte on the wire either way)
_DTYPES = {
    "bool": np.bool_,
    "byte": np.int8,
    "char": np.uint8,
    "int8": np.int8,
    "int16": np.int16,
    "int32": np.int32,
    "int64": np.int64,
    "uint8": np.uint8,
    "uint16": np.uint16,
    "uint32": np.uint32,
    "uint64": np.uint64,
    "float32": np.float32,
    "float64": np.float64,
}


def require_cyclonedds() -> Any:
    """The ``cyclonedds`` package, or a ConfigError with the install line (it is an optional dependency)."""
    try:
        import cyclonedds
        import cyclonedds.idl
        import cyclonedds.idl.types
    except ImportError as exc:
        missing = "live ROS 2 needs Cyclone DDS (the cyclonedds package), which is not installed"
        raise ConfigError("", missing, INSTALL) from exc
    except Exception as exc:  # installed, but its C library failed to load (CycloneDDSLoaderException)
        raise ConfigError("", f"Cyclone DDS could not be loaded: {exc}", f"reinstall it: {INSTALL}") from exc
    return cyclonedds


def dds_type_name(msgtype: str) -> str:
    """The DDS type name ROS 2's middlewares give a message: ``pkg/msg/Name`` -> ``pkg::msg::dds_::Name_``."""
    *namespace, name = msgtype.split("/")
    return "::".join([*namespace, "dds_", f"{name}_"])


def _fields(msgtype: str) -> list[tuple[str, Any]]:
    """The fields of ``msgtype`` in order, as (name, description) pairs of rosbags' type store."""
    store = typestore()
    if msgtype not in store.fielddefs:
        close = difflib.get_close_matches(msgtype, list(store.fielddefs), n=1)
        hint = f"did you mean '{close[0]}'?" if close else "give a ROS 2 message type, e.g. geometry_msgs/msg/Twist"
        raise ConfigError("msgtype", f"'{msgtype}' is not a message of ROS 2 Jazzy's type store", hint)
    return list(store.fielddefs[msgtype][1])


def _base_type(name: str, bound: int, where: str) -> Any:
    """The cyclonedds annotation of a ROS base type (a ``char`` is ``uint8`` and a ``byte`` one byte, as in ROS 2)."""
    types = require_cyclonedds().idl.types
    if name == "string":
        return types.bounded_str[bound] if bound else str
    if name == "bool":
        return bool
    if name == "byte":
        return types.int8  # rosbags reads a byte as signed
    if name == "char":
        return types.uint8
    if name in _DTYPES:
        return getattr(types, name)
    raise ConfigError("msgtype", f"{where} is a {name}, which ddtrack does not carry over DDS", "")


def _annotation(desc: Any, where: str) -> Any:
    """The cyclonedds annotation of one field description (base, message, array or sequence)."""
    node, info = desc
    if node == _BASE:
        return _base_type(info[0], info[1], where)
    if node == _NAME:
        return idl_type(info)
    types = require_cyclonedds().idl.types
    element = _annotation(info[0], where)
    if node == _ARRAY:
        return types.array[element, info[1]]
    return types.sequence[element, info[1]] if info[1] else types.sequence[element]


@cache
def idl_type(msgtype: str) -> type[Any]:
    """The Cyclone DDS type (an ``IdlStruct``) of the ROS 2 message ``msgtype``, generated from its definition.

    Parameters
    ----------
    msgtype : str
        The ROS 2 name, e.g. ``"nav_msgs/msg/Odometry"``; nested messages get types of their own.

    Returns
    -------
    type
        A final struct named as ROS 2 names it on DDS (``nav_msgs::msg::dds_::Odometry_``), with the fields in
        their order, each typed as ROS 2's IDL types it (``float64[36]`` an array, ``string[]`` a sequence).
    """
    idl = require_cyclonedds().idl
    annotations = {name: _annotation(desc, f"{msgtype}.{name}") for name, desc in _fields(msgtype)}
    return idl.make_idl_struct(msgtype.replace("/", "__"), dds_type_name(msgtype), annotations)


def _numbers(value: Any, desc: Any) -> Any:
    """An array or sequence of numbers as cyclonedds takes it: bytes for ``uint8[N]``, a list otherwise."""
    _, info = desc
    dtype = _DTYPES[info[0][1][0]]
    numbers: np.ndarray = np.asarray(value, dtype=dtype)
    if desc[0] == _ARRAY and dtype is np.uint8:
        return numbers.tobytes()
    return numbers.tolist()


def _outgoing(value: Any, desc: Any) -> Any:
    """One field's value of a rosbags message as the generated type's field takes it."""
    node, info = desc
    if node == _BASE:
        return value
    if node == _NAME:
        return to_idl(value, info)
    element = info[0]
    if element[0] == _BASE and element[1][0] != "string":
        return _numbers(value, desc)
    return [_outgoing(item, element) for item in value]


def _incoming(value: Any, desc: Any) -> Any:
    """One field's value of a generated type's instance as rosbags holds it (numbers in numpy arrays)."""
    node, info = desc
    if node == _BASE:
        return value
    if node == _NAME:
        return from_idl(value, info)
    element = info[0]
    if element[0] == _BASE and element[1][0] != "string":
        dtype = _DTYPES[element[1][0]]
        if isinstance(value, bytes | bytearray):
            return np.frombuffer(value, dtype=dtype).copy()
        return np.asarray(value, dtype=dtype)
    return [_incoming(item, element) for item in value]


def to_idl(message: Any, msgtype: str | None = None) -> Any:
    """The generated type's instance of a rosbags message (nested messages and sequences converted in depth).

    Parameters
    ----------
    message : rosbags message
        An instance of ``typestore().types[msgtype]``, e.g. from :func:`ddtrack.ros.messages.twist`.
    msgtype : str, optional
        Its ROS 2 type name; read from the message (``__msgtype__``) when not given.

    Returns
    -------
    IdlStruct
        An instance of :func:`idl_type` of ``msgtype``, with the same values.
    """
    msgtype = msgtype or message.__msgtype__
    values = {name: _outgoing(getattr(message, name), desc) for name, desc in _fields(msgtype)}
    return idl_type(msgtype)(**values)


def from_idl(sample: Any, msgtype: str) -> Any:
    """The rosbags message of a generated type's instance, the inverse of :func:`to_idl`.

    Parameters
    ----------
    sample : IdlStruct
        An instance of :func:`idl_type` of ``msgtype``, e.g. as a DDS reader takes it.
    msgtype : str
        Its ROS 2 type name.

    Returns
    -------
    rosbags message
        An instance of ``typestore().types[msgtype]``, numbers in numpy arrays as rosbags reads them from a bag.
    """
    values = {name: _incoming(getattr(sample, name), desc) for name, desc in _fields(msgtype)}
    return typestore().types[msgtype](**values)


def serialize(message: Any, msgtype: str | None = None) -> bytes:
    """The bytes Cyclone DDS writes for a message: its 4-byte encapsulation header (``CDR_LE``) and plain CDR.

    Parameters
    ----------
    message : rosbags message
        The message to serialize.
    msgtype : str, optional
        Its ROS 2 type name (read from the message when not given).

    Returns
    -------
    bytes
        ``00 01 00 00`` and the message in XCDR1, little-endian, with no trailing padding.
    """
    little = require_cyclonedds().idl.Endianness.Little
    return bytes(to_idl(message, msgtype).serialize(endianness=little, use_version_2=False))


def deserialize(data: bytes, msgtype: str) -> Any:
    """The rosbags message of CDR bytes with their encapsulation header (as :func:`serialize` writes them).

    Parameters
    ----------
    data : bytes
        The encapsulation header and the payload, as DDS carries them or a ROS 2 bag stores them.
    msgtype : str
        The message's ROS 2 type name.

    Returns
    -------
    rosbags message
        The message, numbers in numpy arrays.
    """
    return from_idl(idl_type(msgtype).deserialize(bytes(data)), msgtype)
