"""The structure check of a physics state (the second gate of :mod:`llcps.sim.snapshot`).

A ``.bullet`` file is parsed chunk by chunk and compared with a *reference*: a state
the engine saved of the same scene freshly built. Header and type catalogue (DNA) must
be identical, shapes byte for byte; every multibody, link and collider chunk must have
the reference's struct type, count and size, its pointers must lead to the same
chunks, its counts and joint types must match and its pose and velocities must be
finite; every contact manifold must point at colliders (or nothing) and hold at most
four points. Pure Python, a few milliseconds.
"""

from __future__ import annotations

import math
import re
import struct
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, Sequence

from llcps.sim.snapshot import BULLET_HEADER, StateError

_CHUNK = struct.Struct("<4siQii")  # code, length, old pointer, struct index, count (64-bit, little endian)
_MANIFOLD_TYPE = 1025  # BT_PERSISTENT_MANIFOLD_TYPE
_MAX_MANIFOLD_POINTS = 4
_STATE_LIMIT = 1e6  # m, rad, m/s: anything beyond is not a state of these scenes


# --------------------------------------------------------------------------- the .bullet format


@dataclass(frozen=True)
class Chunk:
    """One chunk of a ``.bullet`` file: a struct array with the address it had when saved."""

    code: bytes
    length: int
    old: int
    sdna: int
    count: int
    offset: int  # of the data, in the file


@dataclass(frozen=True)
class Field:
    """A leaf field of a struct, flattened: byte offset, element type and element count."""

    name: str
    kind: str  # "ptr", or a basic type: "double", "float", "int", "short", "char", ...
    offset: int
    count: int


@dataclass(frozen=True, eq=False)  # hashed by identity: parse_catalogue hands out one per DNA
class Catalogue:
    """The type catalogue (SDNA) a ``.bullet`` file carries: struct names, sizes and fields."""

    names: tuple[str, ...]
    sizes: tuple[int, ...]
    fields: tuple[tuple[Field, ...], ...]

    def index(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            raise StateError(f"the physics state's catalogue has no struct {name}") from None


_BASIC = {"char": 1, "uchar": 1, "short": 2, "ushort": 2, "int": 4, "long": 4, "ulong": 4, "float": 4, "double": 8}
_ARRAY = re.compile(r"\[(\d+)\]")


def parse_chunks(raw: bytes) -> list[Chunk]:
    """Walk the chunks of a ``.bullet`` file, checking that every one lies inside it."""
    if len(raw) < 12 or not raw.startswith(BULLET_HEADER) or raw[7:9] != b"-v":
        raise StateError("not a physics state of this engine: unknown header", hint="states come from World.serialize_state()")
    chunks: list[Chunk] = []
    pos = 12
    while pos < len(raw):
        if pos + _CHUNK.size > len(raw):
            raise StateError(f"the physics state is cut off inside a chunk header at byte {pos}")
        code, length, old, sdna, count = _CHUNK.unpack_from(raw, pos)
        pos += _CHUNK.size
        if length < 0 or count < 1 or pos + length > len(raw):
            raise StateError(f"chunk {len(chunks)} of the physics state has an impossible size")
        chunks.append(Chunk(code, length, old, sdna, count, pos))
        pos += length
        if code == b"ENDB":
            break
    return chunks


#: References are checked against again and again (bytes cache their hash, so the key is cheap).
_reference_chunks = lru_cache(maxsize=32)(parse_chunks)


def _cstrings(data: bytes, pos: int, n: int) -> tuple[list[str], int]:
    out = []
    for _ in range(n):
        end = data.index(b"\0", pos)
        out.append(data[pos:end].decode("ascii"))
        pos = end + 1
    return out, pos


def _section(data: bytes, pos: int, tag: bytes) -> int:
    pos = (pos + 3) & ~3
    if data[pos : pos + 4] != tag:
        raise ValueError(f"expected {tag!r}")
    return pos + 4


@lru_cache(maxsize=4)
def parse_catalogue(dna: bytes) -> Catalogue:
    """Read an SDNA block (only ever a reference's: the checked state must carry identical bytes)."""
    try:
        if not dna.startswith(b"SDNA"):
            raise ValueError("no SDNA tag")
        pos = _section(dna, 4, b"NAME")
        (n,) = struct.unpack_from("<i", dna, pos)
        names, pos = _cstrings(dna, pos + 4, n)
        pos = _section(dna, pos, b"TYPE")
        (n,) = struct.unpack_from("<i", dna, pos)
        types, pos = _cstrings(dna, pos + 4, n)
        pos = _section(dna, pos, b"TLEN")
        lengths = struct.unpack_from(f"<{n}h", dna, pos)
        pos = _section(dna, pos + 2 * n, b"STRC")
        (n_structs,) = struct.unpack_from("<i", dna, pos)
        pos += 4
        layouts: list[tuple[int, list[tuple[int, int]]]] = []
        for _ in range(n_structs):
            type_index, n_fields = struct.unpack_from("<hh", dna, pos)
            members = [struct.unpack_from("<hh", dna, pos + 4 + 4 * i) for i in range(n_fields)]
            layouts.append((type_index, members))
            pos += 4 + 4 * n_fields
    except (ValueError, struct.error, UnicodeDecodeError, IndexError) as exc:
        raise StateError(f"the physics state's type catalogue is unreadable: {exc}") from exc
    by_type = {type_index: i for i, (type_index, _) in enumerate(layouts)}

    def flatten(index: int, prefix: str, depth: int) -> list[Field]:
        if depth > 16:
            raise StateError("the physics state's type catalogue nests too deeply")
        out: list[Field] = []
        offset = 0
        for member_type, member_name in layouts[index][1]:
            name = names[member_name]
            count = math.prod(int(k) for k in _ARRAY.findall(name))
            base = prefix + _ARRAY.sub("", name).lstrip("*(").split(")")[0]
            if name.startswith(("*", "(*")):
                out.append(Field(base, "ptr", offset, count))
                offset += 8 * count
                continue
            size = lengths[member_type]
            if member_type in by_type:
                for k in range(count):
                    sub = f"{base}[{k}]." if count > 1 else f"{base}."
                    out.extend(Field(f.name, f.kind, f.offset + offset + k * size, f.count) for f in flatten(by_type[member_type], sub, depth + 1))
            else:
                out.append(Field(base, types[member_type], offset, count))
            offset += size * count
        return out

    return Catalogue(
        names=tuple(types[t] for t, _ in layouts),
        sizes=tuple(lengths[t] for t, _ in layouts),
        fields=tuple(tuple(flatten(i, "", 0)) for i in range(len(layouts))),
    )


def _dna(raw: bytes, chunks: Sequence[Chunk]) -> bytes:
    found = [c for c in chunks if c.code == b"DNA1"]
    if len(found) != 1:
        raise StateError("the physics state has no single type catalogue")
    return raw[found[0].offset : found[0].offset + found[0].length]


# --------------------------------------------------------------------------- the structure check

#: Chunks whose bytes never change while a scene runs (collision shapes and their arrays).
_STATIC_STRUCTS = frozenset(
    {"btCompoundShapeData", "btCompoundShapeChildData", "btConvexInternalShapeData", "btConvexHullShapeData",
     "btStaticPlaneShapeData", "btCylinderShapeData", "btCapsuleShapeData", "btVector3DoubleData", "btVector3FloatData",
     "btSphereShapeData", "btBoxShapeData", "btMultiSphereShapeData", "btPositionAndRadius"}
)  # fmt: skip
#: Integer fields the engine uses as counts, indices or types: they must equal the reference's.
_FIXED_INTS = re.compile(
    r"(^|\.)m_(numLinks|parentIndex|jointType|dofCount|posVarCount|link|numChildShapes|childShapeType|"
    r"numUnscaledPoints|shapeType|numIterations|solverMode|internalType|upAxis)$"
)
#: Doubles that carry the pose and motion the engine integrates: they must be finite and plausible.
_STATE_DOUBLES = re.compile(
    r"^(m_baseWorldPosition|m_baseWorldOrientation|m_baseLinearVelocity|m_baseAngularVelocity)\.|^(m_jointPos|m_jointVel)$"
)


def _value(raw: bytes, field: Field, at: int, k: int) -> Any:
    if field.kind == "ptr":
        return struct.unpack_from("<Q", raw, at + field.offset + 8 * k)[0]
    size = _BASIC[field.kind]
    fmt = {1: "<b", 2: "<h", 4: "<f" if field.kind == "float" else "<i", 8: "<d"}[size]
    return struct.unpack_from(fmt, raw, at + field.offset + size * k)[0]


@dataclass(frozen=True)
class _Plan:
    """What to read of one struct: its pointers, its fixed integers and its state doubles,
    each as one ``struct.Struct`` that skips the bytes in between."""

    pointers: struct.Struct
    pointer_names: tuple[str, ...]
    ints: struct.Struct
    int_names: tuple[str, ...]
    doubles: struct.Struct
    double_names: tuple[str, ...]


def _gather(picked: list[tuple[int, str, int, str]]) -> tuple[struct.Struct, tuple[str, ...]]:
    fmt, names, pos = ["<"], [], 0
    for offset, code, size, name in sorted(picked):
        if offset > pos:
            fmt.append(f"{offset - pos}x")
        fmt.append(code)
        names.append(name)
        pos = offset + size
    return struct.Struct("".join(fmt)), tuple(names)


@lru_cache(maxsize=256)
def _plan(catalogue: Catalogue, sdna: int) -> _Plan:
    pointers, ints, doubles = [], [], []
    for f in catalogue.fields[sdna]:
        for k in range(f.count):
            if f.kind == "ptr":
                pointers.append((f.offset + 8 * k, "Q", 8, f.name))
            elif f.kind in ("int", "short") and _FIXED_INTS.search(f.name):
                size = _BASIC[f.kind]
                ints.append((f.offset + size * k, "i" if size == 4 else "h", size, f.name))
            elif f.kind == "double" and _STATE_DOUBLES.search(f.name):
                doubles.append((f.offset + 8 * k, "d", 8, f.name))
    return _Plan(*_gather(pointers), *_gather(ints), *_gather(doubles))


def check_state(raw: bytes, reference: bytes) -> None:
    """Refuse a raw state whose structure differs from ``reference`` (see the module docstring).

    Args:
        raw: the decompressed state to check.
        reference: a state the engine saved of the same scene (``World.reference_state``).

    Raises:
        StateError: the first difference found.
    """
    ref_chunks = _reference_chunks(reference)
    chunks = parse_chunks(raw)
    if raw[:12] != reference[:12]:
        raise StateError(f"the physics state was saved by another engine build ({raw[:12]!r})")
    dna = _dna(reference, ref_chunks)
    if _dna(raw, chunks) != dna:
        raise StateError("the physics state's type catalogue differs from this engine's")
    catalogue = parse_catalogue(dna)
    manifold = catalogue.index("btPersistentManifoldDoubleData")
    collider = catalogue.index("btMultiBodyLinkColliderDoubleData")
    bodies = [c for c in chunks if c.code != b"CONT"]
    ref_bodies = [c for c in ref_chunks if c.code != b"CONT"]
    shape = [(c.code, c.sdna, c.count, c.length) for c in bodies]
    if shape != [(c.code, c.sdna, c.count, c.length) for c in ref_bodies]:
        raise StateError("the physics state holds other bodies, shapes or links than its scene")
    for chunk in chunks:
        # The engine may pad a chunk past its struct array (a manifold: 8 bytes); never short of it.
        if chunk.sdna >= 0 and (chunk.sdna >= len(catalogue.sizes) or chunk.length < chunk.count * catalogue.sizes[chunk.sdna]):
            raise StateError(f"a {chunk.code.decode('latin-1')} chunk of the physics state has the wrong size")
    index = {c.old: i for i, c in enumerate(bodies)}
    ref_index = {c.old: i for i, c in enumerate(ref_bodies)}
    colliders = {0} | {c.old for c in bodies if c.sdna == collider}
    for chunk, ref in zip(bodies, ref_bodies):
        if chunk.code == b"DNA1":
            continue
        name = catalogue.names[chunk.sdna]
        if name in _STATIC_STRUCTS:
            if raw[chunk.offset : chunk.offset + chunk.length] != reference[ref.offset : ref.offset + ref.length]:
                raise StateError(f"a collision shape of the physics state differs from its scene ({name})")
            continue
        size, plan = catalogue.sizes[chunk.sdna], _plan(catalogue, chunk.sdna)
        for element in range(chunk.count):
            at, ref_at = chunk.offset + element * size, ref.offset + element * size
            got, expected = plan.pointers.unpack_from(raw, at), plan.pointers.unpack_from(reference, ref_at)
            for field, value, want in zip(plan.pointer_names, got, expected):
                if (value == 0) != (want == 0) or (value and index.get(value, -1) != ref_index.get(want)):
                    raise StateError(f"{name}.{field} of the physics state points elsewhere than its scene's")
            got, expected = plan.ints.unpack_from(raw, at), plan.ints.unpack_from(reference, ref_at)
            if got != expected:
                field, value = next((f, v) for f, v, w in zip(plan.int_names, got, expected) if v != w)
                raise StateError(f"{name}.{field} of the physics state differs from its scene's ({value})")
            for field, value in zip(plan.double_names, plan.doubles.unpack_from(raw, at)):
                if not abs(value) < _STATE_LIMIT:
                    raise StateError(f"{name}.{field} of the physics state is not a plausible number ({value})")
    fields = {f.name: f for f in catalogue.fields[manifold]}
    for chunk in chunks:
        if chunk.code != b"CONT":
            continue
        if chunk.sdna != manifold or chunk.count != 1:
            raise StateError("a contact of the physics state is not a contact manifold")
        points = _value(raw, fields["m_numCachedPoints"], chunk.offset, 0)
        if not 0 <= points <= _MAX_MANIFOLD_POINTS or _value(raw, fields["m_objectType"], chunk.offset, 0) != _MANIFOLD_TYPE:
            raise StateError(f"a contact manifold of the physics state is malformed ({points} points)")
        for body in ("m_body0", "m_body1"):
            if _value(raw, fields[body], chunk.offset, 0) not in colliders:  # (or null: the engine saves some so)
                raise StateError("a contact manifold of the physics state points at no body of its scene")


def clear_caches() -> None:
    """Forget the parsed references, catalogues and read plans."""
    _reference_chunks.cache_clear()
    parse_catalogue.cache_clear()
    _plan.cache_clear()
