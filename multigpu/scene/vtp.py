"""VTK's XML PolyData (``.vtp``), which ParaView writes for surfaces and meshio does not read:
turned into the XML UnstructuredGrid meshio does read, then read by meshio.

Both formats share everything but the cells: a PolyData piece keeps its polygons in ``Polys``
(``connectivity`` and ``offsets``), an UnstructuredGrid piece in ``Cells`` (the same two, and the
cells' ``types``). So the file's header (before any raw appended data, which stays byte for byte
where its offsets say) is rewritten: ``PolyData`` becomes ``UnstructuredGrid``, each piece's
``Polys`` its ``Cells`` with a ``types`` array of VTK polygons (drawn triangulated, as every
polygon is), ``NumberOfPolys`` its ``NumberOfCells``. Vertices, lines and triangle strips are not
surfaces here: left out and counted (``notes``). Every encoding meshio reads stays readable
(ASCII, inline binary, appended raw or base64, compressed): ``scene/simulation.read`` hands the
rewritten bytes to meshio. Pure bytes to bytes: no meshio, no MPI, no GL.
"""

from __future__ import annotations

import re

from multigpu.errors import InputError

#: the VTK cell type of a polygon (meshio reads it as ``polygon``; the loader triangulates it)
VTK_POLYGON = 7
_OTHERS = ("Verts", "Lines", "Strips")


def _piece(piece: bytes, notes: list[str], kept: list[bytes]) -> bytes:
    """One ``<Piece ...>...</Piece>`` as an UnstructuredGrid's piece; the arrays of its vertices,
    lines and strips go to ``kept`` (meshio walks raw appended data array by array, by offset)."""
    def count(name: bytes) -> int:
        got = re.search(rb"NumberOf" + name + rb'="\s*(\d+)\s*"', piece)
        return int(got[1]) if got else 0

    for other in _OTHERS:
        tag = other.encode()
        n = count(tag)
        if n:
            notes.append(f"{n} {other.lower()} left out (not surfaces)")
        for block in re.findall(rb"<" + tag + rb"\b[^>]*>(.*?)</" + tag + rb">", piece, flags=re.S):
            kept.append(re.sub(rb'Name="', b'Name="vtp_' + tag.lower() + b"_", block))
        piece = re.sub(rb"<" + tag + rb"\b[^>]*>.*?</" + tag + rb">", b"", piece, flags=re.S)
        piece = re.sub(rb"<" + tag + rb"\s*/>", b"", piece)
    polys = count(b"Polys")
    types = b'<DataArray type="UInt8" Name="types" format="ascii">' + b" ".join([b"7"] * polys) + b"</DataArray>"
    if re.search(rb"<Polys\b[^/]*?>", piece):
        piece = re.sub(rb"<Polys\b[^>]*?>", b"<Cells>", piece)
        piece = piece.replace(b"</Polys>", types + b"</Cells>")
    elif re.search(rb"<Polys\s*/>", piece):
        piece = re.sub(rb"<Polys\s*/>", b"<Cells>" + types + b"</Cells>", piece)
    else:
        piece = piece.replace(b"</Piece>", b"<Cells>" + types + b"</Cells></Piece>")
    return re.sub(rb'NumberOfPolys="', b'NumberOfCells="', piece, count=1)


def as_unstructured(data: bytes, where: str) -> tuple[bytes, list[str]]:
    """A ``.vtp`` file's bytes as an equivalent ``.vtu``'s, and what was left out."""
    cut = data.find(b"<AppendedData")
    head, tail = (data, b"") if cut < 0 else (data[:cut], data[cut:])
    if not re.search(rb'<VTKFile[^>]*type="PolyData"', head) or b"<PolyData" not in head:
        raise InputError.of("model", f"{where}: not a VTK XML PolyData file (no VTKFile of type PolyData)")
    notes: list[str] = []
    kept: list[bytes] = []
    head = re.sub(rb"<Piece\b.*?</Piece>", lambda m: _piece(m.group(0), notes, kept), head, flags=re.S)
    head = head.replace(b'type="PolyData"', b'type="UnstructuredGrid"', 1)
    head = head.replace(b"</PolyData>", b"</UnstructuredGrid>", 1)
    field = b"<FieldData>" + b"".join(kept) + b"</FieldData>" if kept else b""  # read, never drawn
    head = re.sub(rb"<PolyData\b([^>]*)>", lambda m: b"<UnstructuredGrid" + m.group(1) + b">" + field, head, count=1)
    return head + tail, notes
