"""A structural check of a C3D file before ezc3d reads it.

ezc3d trusts the sizes a C3D file states: a file cut short inside its parameter section, or a
parameter whose dimensions point past the section, can make it loop forever or crash the
interpreter.  :func:`check_c3d_structure` walks the header and the parameter section as the C3D
format defines them (C3D.ORG, "The C3D File Format User Guide", 2008: chapter 2, the header
section; chapter 3, the parameter section) and refuses, with one line naming the file, one whose
stated sizes do not fit in it.
"""
from __future__ import annotations

import struct
from pathlib import Path

from ..errors import TrialError

__all__ = ["check_c3d_structure"]

_BLOCK = 512
#: processor type byte of the parameter section -> struct byte order (84 Intel, 85 DEC, 86 MIPS)
_ORDER = {84: "<", 85: "<", 86: ">"}
#: parameter data types -> bytes per element (-1 char, 1 byte, 2 int16, 4 float)
_SIZES = {-1: 1, 1: 1, 2: 2, 4: 4}


def check_c3d_structure(path) -> None:
    """Raise :class:`~pinmsk.errors.TrialError` if the C3D file's header or parameter section states
    sizes that do not fit in the file (see the module docstring); return None if they do."""
    path = Path(path)
    data = path.read_bytes()
    where = f"{path}: not a readable C3D file"
    if len(data) < _BLOCK:
        raise TrialError(f"{where}: {len(data)} bytes, shorter than its 512-byte header")
    if data[1] != 0x50:
        raise TrialError(f"{where}: byte 2 of the header is {data[1]}, not 80 (the C3D key)")
    start = (data[0] - 1) * _BLOCK
    if data[0] < 2 or start + 4 > len(data):
        raise TrialError(f"{where}: the header puts the parameter section at block {data[0]}, "
                         f"outside the file ({len(data)} bytes)")
    n_blocks, processor = data[start + 2], data[start + 3]
    order = _ORDER.get(processor)
    if order is None:
        raise TrialError(f"{where}: unknown processor type {processor} in the parameter section (84, 85 or 86)")
    end = start + n_blocks * _BLOCK
    if n_blocks == 0 or end > len(data):
        raise TrialError(f"{where}: the parameter section states {n_blocks} blocks of 512 bytes, but the file "
                         f"has {len(data) - start} bytes from its start; the file may be cut short")
    _walk_parameters(data, start + 4, end, order, where)
    points, = struct.unpack_from(order + "H", data, 2)
    analogs, = struct.unpack_from(order + "H", data, 4)
    first, last = struct.unpack_from(order + "HH", data, 6)
    scale, = struct.unpack_from(order + "f", data, 12)
    data_block, = struct.unpack_from(order + "H", data, 16)
    if last >= first > 0 and data_block > 0:
        frames = last - first + 1
        size = 4 if scale < 0 else 2
        need = (data_block - 1) * _BLOCK + frames * (4 * points + analogs) * size
        if (data_block - 1) * _BLOCK < end or need > len(data):
            raise TrialError(f"{where}: the header states {frames} frames of {points} points and {analogs} analog "
                             f"samples from block {data_block} ({need} bytes), but the file has {len(data)}; "
                             "the file may be cut short")


def _walk_parameters(data: bytes, pos: int, end: int, order: str, where: str) -> None:
    """Follow the parameter section's records from ``pos`` to its last (offset 0) or to ``end``."""
    for _ in range(100_000):
        if pos + 2 > end:
            raise TrialError(f"{where}: the parameter section runs past its end (byte {pos})")
        nchar, ident = struct.unpack_from("bb", data, pos)
        if nchar == 0:
            return                                   # the end of the section
        name_end = pos + 2 + abs(nchar)
        if name_end + 2 > end:
            raise TrialError(f"{where}: a parameter name at byte {pos} runs past the parameter section")
        offset, = struct.unpack_from(order + "h", data, name_end)
        body = name_end + 2
        if ident > 0:                                # a parameter: type, dimensions, data
            if body + 2 > end:
                raise TrialError(f"{where}: parameter at byte {pos} runs past the parameter section")
            kind, ndims = struct.unpack_from("bb", data, body)
            if kind not in _SIZES or ndims < 0 or body + 2 + ndims > end:
                raise TrialError(f"{where}: parameter at byte {pos} has type {kind} and {ndims} dimensions "
                                 "(types are -1, 1, 2, 4)")
            if kind == -1 and ndims == 0:            # ezc3d cannot read a character scalar (it crashes)
                raise TrialError(f"{where}: character parameter at byte {pos} has no dimensions")
            count = 1
            for d in data[body + 2:body + 2 + ndims]:
                count *= d
            stop = body + 2 + ndims + count * _SIZES[kind]
            if stop + 1 > end:
                raise TrialError(f"{where}: parameter at byte {pos} states {count} values that run past the "
                                 "parameter section")
        else:
            stop = body
        if stop + 1 > end:
            raise TrialError(f"{where}: the record at byte {pos} runs past the parameter section")
        stop += 1 + data[stop]                       # the description and its length
        nxt = name_end + offset
        if stop > end or (offset != 0 and stop > nxt):
            raise TrialError(f"{where}: the record at byte {pos} is longer than the space its offset gives it")
        if offset == 0:
            return                                   # the last record
        if offset < 0 or nxt <= pos or nxt > end:
            raise TrialError(f"{where}: the parameter record at byte {pos} points to byte {nxt}, outside the "
                             "parameter section")
        pos = nxt
    raise TrialError(f"{where}: the parameter section does not end")
