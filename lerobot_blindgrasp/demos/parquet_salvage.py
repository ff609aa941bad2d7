"""The complete row groups of a parquet file whose writer never wrote its footer (a SIGKILL, a full disk):
`salvage(buf, template)` walks the page headers, cuts after the last complete row group and builds a footer for those
bytes from the one pyarrow writes for `template` (a one-row table of the file's schema). Hand-written because
pyarrow, pandas and datasets all start from the footer; the Thrift compact codec covers what parquet's metadata uses.
"""

from __future__ import annotations

import io
import struct
from dataclasses import dataclass

MAGIC = b"PAR1"
DICTIONARY_PAGE = 2
_STOP, _TRUE, _FALSE, _BYTE, _I16, _I32, _I64, _DOUBLE, _BINARY, _LIST, _SET, _MAP, _STRUCT = range(13)


class Truncated(Exception):
    """The bytes end inside a Thrift structure."""


# --- Thrift compact protocol: a struct is {field id: (type, value)}, a list is (element type, [values]) ----------
def _varint(buf: bytes, pos: int) -> tuple[int, int]:
    shift = result = 0
    while True:
        if pos >= len(buf):
            raise Truncated
        b = buf[pos]
        pos += 1
        result |= (b & 0x7F) << shift
        if not b & 0x80:
            return result, pos
        shift += 7


def _zigzag(n: int) -> int:
    return (n >> 1) ^ -(n & 1)


def _value(buf: bytes, pos: int, t: int):
    if t in (_TRUE, _FALSE):  # only inside lists: one byte each
        return buf[pos] == 1, pos + 1
    if t == _BYTE:
        return buf[pos], pos + 1
    if t in (_I16, _I32, _I64):
        n, pos = _varint(buf, pos)
        return _zigzag(n), pos
    if t == _DOUBLE:
        return struct.unpack_from("<d", buf, pos)[0], pos + 8
    if t == _BINARY:
        n, pos = _varint(buf, pos)
        if pos + n > len(buf):
            raise Truncated
        return bytes(buf[pos : pos + n]), pos + n
    if t in (_LIST, _SET):
        head = buf[pos]
        pos += 1
        size, et = head >> 4, head & 0x0F
        if size == 15:
            size, pos = _varint(buf, pos)
        items = []
        for _ in range(size):
            v, pos = _value(buf, pos, et)
            items.append(v)
        return (et, items), pos
    if t == _STRUCT:
        return read_struct(buf, pos)
    raise ValueError(f"Thrift type {t} is not used by parquet metadata")


def read_struct(buf: bytes, pos: int = 0) -> tuple[dict, int]:
    fields: dict[int, tuple[int, object]] = {}
    last = 0
    while True:
        if pos >= len(buf):
            raise Truncated
        head = buf[pos]
        pos += 1
        if head == _STOP:
            return fields, pos
        delta, t = head >> 4, head & 0x0F
        if delta:
            fid = last + delta
        else:
            n, pos = _varint(buf, pos)
            fid = _zigzag(n)
        if t in (_TRUE, _FALSE):
            fields[fid] = (t, t == _TRUE)
        else:
            value, pos = _value(buf, pos, t)
            fields[fid] = (t, value)
        last = fid


def _put_varint(out: bytearray, n: int) -> None:
    while True:
        if n < 0x80:
            out.append(n)
            return
        out.append((n & 0x7F) | 0x80)
        n >>= 7


def _put_value(out: bytearray, t: int, v) -> None:
    if t in (_TRUE, _FALSE):
        out.append(1 if v else 2)
    elif t == _BYTE:
        out.append(v & 0xFF)
    elif t in (_I16, _I32, _I64):
        _put_varint(out, (v << 1) ^ (v >> 63))
    elif t == _DOUBLE:
        out += struct.pack("<d", v)
    elif t == _BINARY:
        _put_varint(out, len(v))
        out += v
    elif t in (_LIST, _SET):
        et, items = v
        out.append((min(len(items), 15) << 4) | et)
        if len(items) >= 15:
            _put_varint(out, len(items))
        for item in items:
            _put_value(out, et, item)
    elif t == _STRUCT:
        write_struct(out, v)
    else:
        raise ValueError(f"Thrift type {t} is not used by parquet metadata")


def write_struct(out: bytearray, fields: dict) -> None:
    last = 0
    for fid in sorted(fields):
        t, v = fields[fid]
        head_t = (_TRUE if v else _FALSE) if t in (_TRUE, _FALSE) else t
        if 0 < fid - last <= 15:
            out.append(((fid - last) << 4) | head_t)
        else:
            out.append(head_t)
            _put_varint(out, (fid << 1) ^ (fid >> 63))
        if t not in (_TRUE, _FALSE):
            _put_value(out, t, v)
        last = fid
    out.append(_STOP)


# --- pages and row groups ----------------------------------------------------------------------------------------
@dataclass
class Page:
    offset: int
    header_len: int
    kind: int
    compressed: int
    uncompressed: int
    num_values: int


def _pages(buf: bytes) -> list[Page]:
    """Every complete page from the start of the file; stops at the first one cut short or not a page header."""
    pages, pos = [], len(MAGIC)
    while pos < len(buf):
        try:
            header, end = read_struct(buf, pos)
            kind, unc, comp = header[1][1], header[2][1], header[3][1]
            sub = next((header[f][1] for f in (5, 7, 8) if f in header), None)
        except (Truncated, KeyError, ValueError, IndexError, struct.error):
            break
        if sub is None or 1 not in sub or end + comp > len(buf):
            break
        pages.append(Page(pos, end - pos, kind, comp, unc, sub[1][1]))
        pos = end + comp
    return pages


def _chunk(pages: list[Page], start: int, want: int | None) -> int | None:
    """The index after column chunk that starts at pages[start]: `want` values, or (want unknown: the first column
    of a row group) up to the next dictionary page. None when the pages run out first."""
    i, got = start, 0
    while i < len(pages):
        p = pages[i]
        if i > start and p.kind == DICTIONARY_PAGE and (want is None or got >= want):
            return i if want is None or got == want else None
        if p.kind != DICTIONARY_PAGE:
            got += p.num_values
        i += 1
        if want is not None and got == want:
            return i
        if want is not None and got > want:
            return None
    return None


def _template_footer(template) -> dict:
    import pyarrow.parquet as pq

    sink = io.BytesIO()
    pq.write_table(template, sink, compression="snappy", use_dictionary=True)
    data = sink.getvalue()
    (n,) = struct.unpack_from("<i", data, len(data) - 8)
    return read_struct(data, len(data) - 8 - n)[0]


def _column(template_cc: dict, pages: list[Page]) -> tuple[dict, int, int]:
    first, data = pages[0], [p for p in pages if p.kind != DICTIONARY_PAGE]
    comp = sum(p.header_len + p.compressed for p in pages)
    unc = sum(p.header_len + p.uncompressed for p in pages)
    meta = {k: v for k, v in template_cc[3][1].items() if k in (1, 2, 3, 4)}  # type, encodings, path, codec
    meta[5] = (_I64, sum(p.num_values for p in data))
    meta[6], meta[7], meta[9] = (_I64, unc), (_I64, comp), (_I64, data[0].offset)
    if first.kind == DICTIONARY_PAGE:
        meta[11] = (_I64, first.offset)
    return {2: (_I64, first.offset), 3: (_STRUCT, meta)}, comp, unc


def salvage(buf: bytes, template) -> tuple[bytes, int, int]:
    """(a readable parquet file, its rows, the bytes set aside after the last complete row group) from the bytes
    of a footerless file whose schema is `template`'s."""
    fmd = _template_footer(template)
    template_cols = fmd[4][1][1][0][1][1][1]  # row_groups[0].columns
    per_row = [cc[3][1][5][1] for cc in template_cols]  # leaf values per row (a list column holds several)
    pages = _pages(buf) if buf[: len(MAGIC)] == MAGIC else []
    groups, i, rows_total, end = [], 0, 0, len(MAGIC)
    while i < len(pages):
        cols, rows, comp_total, unc_total, j = [], None, 0, 0, i
        for c, tcc in enumerate(template_cols):
            nxt = _chunk(pages, j, None if rows is None else rows * per_row[c])
            if nxt is None:
                break
            col, comp, unc = _column(tcc, pages[j:nxt])
            if rows is None:
                rows, rem = divmod(col[3][1][5][1], per_row[0])
                if rem or not rows:
                    break
            cols.append((_STRUCT, col))
            comp_total, unc_total, j = comp_total + comp, unc_total + unc, nxt
        if len(cols) != len(template_cols):
            break  # the last row group was cut: its bytes are set aside
        rg = {1: (_LIST, (_STRUCT, [c for _, c in cols])), 2: (_I64, unc_total), 3: (_I64, rows)}
        rg.update({5: (_I64, pages[i].offset), 6: (_I64, comp_total), 7: (_I16, len(groups))})
        groups.append(rg)
        rows_total += rows
        end, i = pages[j - 1].offset + pages[j - 1].header_len + pages[j - 1].compressed, j
    fmd[3], fmd[4] = (_I64, rows_total), (_LIST, (_STRUCT, groups))
    footer = bytearray()
    write_struct(footer, fmd)
    out = bytes(buf[:end]) if groups else MAGIC
    return out + bytes(footer) + struct.pack("<i", len(footer)) + MAGIC, rows_total, len(buf) - end
