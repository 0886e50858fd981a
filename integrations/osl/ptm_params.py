"""The parameters of a renderer-layout PTM for the texture-system readers (ptm_occlusion.osl,
ptm_occlusion_learned.osl, the MaterialX nodes, Blender's node group), read from the files'
headers, and for a learned basis the basis parts checked as our Rust reader checks them
(docs/FORMAT.md, "The renderer layout"). Python's standard library only (struct, zlib), so it
runs in Blender's Python, a DCC's, or any pipeline script without OpenEXR or numpy.

    import ptm_params
    p = ptm_params.learned_params("w.ptm.c0.exr")   # a learned file: refuses bad basis parts
    # {"stem": "w.ptm", "basis": "learned11", "terms": 11, "grid": 17, "parts": [...c0..c2],
    #  "basis_parts": [...basis0..basis2]}  -> ptm_occlusion_learned.osl's stem, terms, grid

A refusal is a `ValueError` naming the file and the figures: a missing basis part, one that is
not G x G (G = ptm:learnedGrid) or is tiled (MIP levels), lacks one of R, G, B, A, holds a value
that is not finite, a value past the last term that is not 0 (a table of more terms than the
coefficient planes), or a value other than ptm:learnedTable's; a table whose number of terms is
not the basis's k.
"""
import math
import os
import struct
import zlib

RGBA = ("R", "G", "B", "A")
PIXEL_BYTES = {1: 2, 2: 4}  # HALF, FLOAT
LINES_PER_BLOCK = {0: 1, 2: 1, 3: 16}  # NONE, ZIPS, ZIP


def stem_of(path):
    """`w.ptm.c0.exr`, `w.ptm.basis1.exr`, `w.ptm.exr` → `w.ptm`."""
    s = path[:-4] if path.endswith(".exr") else path
    head, _, tail = s.rpartition(".")
    for prefix in ("c", "basis"):
        if head and tail.startswith(prefix) and tail[len(prefix):].isdigit():
            return head
    return s


def read_header(path):
    """The first header of an OpenEXR file: {name: value} for string, int, double, float,
    stringvector, box2i (a tuple xmin, ymin, xmax, ymax), compression (an int) and chlist (a
    list of (name, pixel type)), plus "__tiled" and "__end" (the offset of the offset table)."""
    with open(path, "rb") as f:
        data = f.read()
    if data[:4] != b"\x76\x2f\x31\x01":
        raise ValueError(f"{path}: not an OpenEXR file")
    out = {"__tiled": bool(struct.unpack_from("<I", data, 4)[0] & 0x200)}
    pos = 8
    while data[pos] != 0:
        name_end = data.index(b"\0", pos)
        type_end = data.index(b"\0", name_end + 1)
        name = data[pos:name_end].decode("utf-8", "replace")
        typ = data[name_end + 1:type_end].decode()
        (size,) = struct.unpack_from("<i", data, type_end + 1)
        value = data[type_end + 5:type_end + 5 + size]
        if typ == "string":
            out[name] = value.decode("utf-8", "replace")
        elif typ == "int":
            out[name] = struct.unpack("<i", value)[0]
        elif typ == "double":
            out[name] = struct.unpack("<d", value)[0]
        elif typ == "float":
            out[name] = struct.unpack("<f", value)[0]
        elif typ == "box2i":
            out[name] = struct.unpack("<4i", value)
        elif typ == "compression":
            out[name] = value[0]
        elif typ == "stringvector":
            texts, i = [], 0
            while i < len(value):
                (n,) = struct.unpack_from("<i", value, i)
                texts.append(value[i + 4:i + 4 + n].decode("utf-8", "replace"))
                i += 4 + n
            out[name] = texts
        elif typ == "chlist":
            chans, i = [], 0
            while value[i] != 0:
                end = value.index(b"\0", i)
                chans.append((value[i:end].decode(), struct.unpack_from("<i", value, end + 1)[0]))
                i = end + 1 + 16
            out[name] = chans
        pos = type_end + 5 + size
    out["__end"] = pos + 1
    out["__data"] = data
    return out


def _unzip(packed, raw_size):
    """OpenEXR's ZIP(S) block: zlib, then the byte predictor undone and the two halves
    interleaved again (a block stored raw when compression did not shrink it)."""
    if len(packed) == raw_size:
        return packed
    t = bytearray(zlib.decompress(packed))
    for i in range(1, len(t)):
        t[i] = (t[i - 1] + t[i] - 128) & 0xFF
    half = (len(t) + 1) // 2
    out = bytearray(len(t))
    out[0::2] = t[:half]
    out[1::2] = t[half:]
    return bytes(out)


def read_pixels(path, header=None):
    """(width, height, {channel: [row-major floats]}) of a scanline OpenEXR file with NONE, ZIPS
    or ZIP compression and HALF or FLOAT channels (what ptm writes for basis parts)."""
    h = header or read_header(path)
    if h["__tiled"]:
        raise ValueError(f"{path}: a tiled file (with MIP levels?); a basis part is a scanline image")
    comp = h.get("compression")
    if comp not in LINES_PER_BLOCK:
        raise ValueError(f"{path}: compression {comp} is not read here (NONE, ZIPS or ZIP)")
    x0, y0, x1, y1 = h["dataWindow"]
    w, ht = x1 - x0 + 1, y1 - y0 + 1
    chans = h["channels"]
    for name, ty in chans:
        if ty not in PIXEL_BYTES:
            raise ValueError(f"{path}: channel {name} is not HALF or FLOAT")
    data, lines = h["__data"], LINES_PER_BLOCK[comp]
    blocks = -(-ht // lines)
    offsets = struct.unpack_from(f"<{blocks}Q", data, h["__end"])
    line_bytes = sum(w * PIXEL_BYTES[ty] for _, ty in chans)
    out = {name: [0.0] * (w * ht) for name, _ in chans}
    for off in offsets:
        y, size = struct.unpack_from("<ii", data, off)
        row0 = y - y0
        n = min(lines, ht - row0)
        raw = _unzip(data[off + 8:off + 8 + size], n * line_bytes) if comp else data[off + 8:off + 8 + size]
        pos = 0
        for r in range(row0, row0 + n):
            for name, ty in chans:
                fmt = "<%d%s" % (w, "e" if ty == 1 else "f")
                out[name][r * w:(r + 1) * w] = struct.unpack_from(fmt, raw, pos)
                pos += w * PIXEL_BYTES[ty]
    return w, ht, out


def _f32(x):
    return struct.unpack("<f", struct.pack("<f", x))[0]


def learned_params(path):
    """The parameters of ptm_occlusion_learned.osl / ND_ptm_occlusion_learned_float for the
    learned PTM that `path` names (any file of its renderer layout), its basis parts checked;
    see the module docstring."""
    stem = stem_of(path)
    c0 = stem + ".c0.exr"
    h = read_header(c0)
    if h.get("ptm:layout") != "rgba/1":
        raise ValueError(f"{c0}: not a PTM in the renderer layout (ptm convert --layout rgba)")
    basis = h.get("ptm:basis", "")
    n = basis[len("learned"):]
    if not basis.startswith("learned") or not n.isdigit() or n.startswith("0") or not 1 <= int(n) <= 16:
        raise ValueError(f"{c0}: basis {basis!r} is not a learned basis (learned1 … learned16)")
    k = int(n)
    grid = h.get("ptm:learnedGrid")
    if not isinstance(grid, int) or not 2 <= grid <= 257:
        raise ValueError(f"{c0}: ptm:learnedGrid is {grid!r}; a grid side is an int in 2..257")
    texts = h.get("ptm:learnedTable")
    if not isinstance(texts, list):
        raise ValueError(f"{c0}: a learned basis needs the string-vector attribute ptm:learnedTable")
    if len(texts) != k:
        raise ValueError(f"{c0}: ptm:learnedTable holds {len(texts)} tables but the basis {basis} "
                         f"has {k} coefficient planes")
    table = []
    for t, text in enumerate(texts):
        words = text.split(" ")
        if len(words) != grid * grid:
            raise ValueError(f"{c0}: ptm:learnedTable term {t} holds {len(words)} values; a "
                             f"{grid}×{grid} grid has {grid * grid}")
        table.append([_f32(float(x)) for x in words])
    parts = [f"{stem}.c{i}.exr" for i in range((k + 4) // 4)]
    for p in parts:
        if not os.path.exists(p):
            raise ValueError(f"{p}: missing coefficient part of {stem} ({basis} has {len(parts)})")
    basis_parts = [f"{stem}.basis{i}.exr" for i in range((k + 3) // 4)]
    for i, p in enumerate(basis_parts):
        name = f"basis part basis{i}"
        if not os.path.exists(p):
            raise ValueError(f"{p}: missing {name} of {stem} ({basis} has basis0..basis{len(basis_parts) - 1})")
        bh = read_header(p)
        for key in ("ptm:basis", "ptm:learnedGrid", "ptm:learnedTable"):
            if bh.get(key) != h.get(key):
                raise ValueError(f"{p}: {name}: {key} differs from part c0's")
        if bh.get("ptm:part") != f"basis{i}":
            raise ValueError(f"{p}: {name}: ptm:part is {bh.get('ptm:part')!r}, expected 'basis{i}'")
        x0, y0, x1, y1 = bh["dataWindow"]
        if (x1 - x0 + 1, y1 - y0 + 1) != (grid, grid):
            raise ValueError(f"{p}: {name} is {x1 - x0 + 1}×{y1 - y0 + 1} but ptm:learnedGrid is "
                             f"{grid}: a basis part is the {grid}×{grid} table")
        if bh["__tiled"]:
            raise ValueError(f"{p}: {name} is tiled (MIP levels?); a basis part is one scanline "
                             "image, the table itself")
        _, _, pix = read_pixels(p, bh)
        for c, ch in enumerate(RGBA):
            term = 4 * i + c
            what = f"B{term}" if term < k else "unused"
            if ch not in pix:
                raise ValueError(f"{p}: {name} lacks channel {ch} ({what})")
            for t, x in enumerate(pix[ch]):
                col, row = t % grid, t // grid
                if not math.isfinite(x):
                    raise ValueError(f"{p}: {name}: channel {ch} ({what}) is {x} at column {col}, "
                                     f"row {row}: not a number a renderer can use")
                if term >= k:
                    if x != 0.0:
                        raise ValueError(f"{p}: {name}: channel {ch} holds {x} at column {col}, "
                                         f"row {row}, but {basis} has {k} terms (B0..B{k - 1}), so "
                                         "this channel is unused and must hold 0")
                elif x != table[term][(grid - 1 - row) * grid + col]:
                    raise ValueError(f"{p}: {name}: {what} is {x} at column {col}, row {row} but "
                                     f"ptm:learnedTable holds {table[term][(grid - 1 - row) * grid + col]} "
                                     "there: the part and the header disagree")
    return {"stem": stem, "basis": basis, "terms": k, "grid": grid, "parts": parts,
            "basis_parts": basis_parts}
