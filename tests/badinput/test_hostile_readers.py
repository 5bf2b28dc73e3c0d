"""Hostile files for the readers: headers that lie about sizes, decompression bombs,
patterns of a billion file names, uncovered extents, overflowing rescales, paths that are
not plain files. Each is refused at once with a ValueError (TypeError/FileNotFoundError
where the project raises those) that names the problem, the file and the value; nothing
hangs, allocates what the header claims, or is filled with invented data.

Every file is built here in ``tmp_path`` (a few hundred bytes, or a few tens of KB for the
bombs); every case runs under a deadline, so a regression fails instead of hanging.
"""

from __future__ import annotations

import base64
import gzip
import os
import struct
import tracemalloc
import warnings
import zlib
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

import tetvr
from tetvr import TetMesh
from tetvr.io.legacy_vtk import read_legacy_vtk
from tetvr.io.meshfile import read_cells
from tetvr.fuse import compose
from tetvr.io.volume_file import read_dicom, read_metaimage, read_nifti, read_nrrd, read_volume, read_vti

from ._util import POINTS, SCALARS, deadline

DEADLINE_S = 5.0
BOMB_BYTES = 32 << 20  # what each bomb inflates to: zeros, ~32 KB compressed
BOMB_PEAK_LIMIT = 8 << 20  # a bounded inflate stays far below it


def _quiet_read(path: Path, *args: object, **kwargs: object) -> TetMesh:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return tetvr.read(path, *args, **kwargs)  # type: ignore[arg-type]


# ---------------------------------------------------------------------------------
# 1. Legacy VTK (the fallback reader of tetvr.mesh.cells): declared counts vs the file
# ---------------------------------------------------------------------------------

_VTK_HEAD = "# vtk DataFile Version 3.0\nhostile\n{mode}\nDATASET UNSTRUCTURED_GRID\n"
_POINTS = "POINTS 5 float\n0 0 0 1 0 0 0 1 0 0 0 1 1 1 1\n"
_ONE_TET = "CELLS 1 5\n4 0 1 2 3\nCELL_TYPES 1\n10\n"

LEGACY_CASES = [
    # name, body after the header, what the message must name
    ("cells-500-million-with-size-minus-one", _POINTS + "CELLS 500000000 8\n-1 0 1 2 3 4 5 6\nCELL_TYPES 1\n10\n",
     r"CELLS 500000000 8.*cannot fit in 8 values"),
    ("cells-size-minus-one", _POINTS + "CELLS 2 8\n-1 0 1 2 3 4 5 6\nCELL_TYPES 2\n10 10\n",
     r"CELLS 2 8.*cell 0 declares -1 nodes"),
    ("cells-size-past-the-list", _POINTS + "CELLS 2 10\n4 0 1 2 3 9 0 1 2 3\nCELL_TYPES 2\n10 10\n",
     r"CELLS 2 10.*cell 1 declares 9 nodes, past the 10 values"),
    ("cells-negative-count", _POINTS + "CELLS -1 5\n4 0 1 2 3\nCELL_TYPES 1\n10\n",
     r"CELLS count: expected an integer >= 0, got '-1'"),
    ("cell-id-beyond-int32", _POINTS + "CELLS 1 5\n4 0 1 2 4294967296\nCELL_TYPES 1\n10\n",
     r"CELLS 1 5.*value 4294967296 does not fit its declared type int32"),
    ("points-negative", "POINTS -3 float\n0 0 0\n" + _ONE_TET, r"POINTS count: expected an integer >= 0, got '-3'"),
    ("points-billion", "POINTS 1000000000 float\n0 0 0\n" + _ONE_TET,
     r"POINTS 1000000000: 3000000000 values are declared, but only \d+ bytes are left"),
    ("cell-types-billion", _POINTS + "CELLS 1 5\n4 0 1 2 3\nCELL_TYPES 1000000000\n10\n",
     r"CELL_TYPES 1000000000: 1000000000 values are declared"),
    ("point-data-billion", _POINTS + _ONE_TET + "POINT_DATA 1000000000\nSCALARS s float 1\nLOOKUP_TABLE default\n0\n",
     r"SCALARS 's' in POINT_DATA 1000000000: 1000000000 values are declared"),
    ("field-billion-tuples", _POINTS + _ONE_TET + "POINT_DATA 5\nFIELD f 1\nt 1 1000000000 float\n0\n",
     r"FIELD array 't': 1000000000 values are declared"),
    ("lookup-table-negative", _POINTS + _ONE_TET + "LOOKUP_TABLE t -1\n", r"LOOKUP_TABLE size: expected an integer >= 0"),
    ("offsets-not-rising", _POINTS + "CELLS 2 4\nOFFSETS vtktypeint64\n0 9\nCONNECTIVITY vtktypeint64\n0 1 2 3\n"
     "CELL_TYPES 1\n10\n", r"OFFSETS must rise from 0 to 4"),
]


@pytest.mark.parametrize("body,match", [c[1:] for c in LEGACY_CASES], ids=[c[0] for c in LEGACY_CASES])
def test_legacy_vtk_counts_are_bounded_by_the_file(tmp_path, body, match):
    path = tmp_path / "hostile.vtk"
    path.write_text(_VTK_HEAD.format(mode="ASCII") + body)
    with deadline(DEADLINE_S, "read_legacy_vtk"), pytest.raises(ValueError, match=match) as info:
        read_legacy_vtk(path)
    assert "hostile.vtk" in str(info.value)


def test_the_223_byte_file_through_read(tmp_path):
    """The reported file: meshio refuses it, the fallback used to allocate 3.7 GiB and spin."""
    path = tmp_path / "cells.vtk"
    path.write_text(_VTK_HEAD.format(mode="ASCII") + _POINTS + "CELLS 500000000 8\n-1 0 1 2 3 4 5 6\n"
                    "CELL_TYPES 1\n10\n")
    with deadline(DEADLINE_S, "read"), pytest.raises(ValueError, match=r"cells\.vtk.*CELLS 500000000 8"):
        _quiet_read(path)


@pytest.mark.parametrize("keyword", ["POINTS", "CELLS", "CELL_TYPES", "SCALARS"])
def test_binary_legacy_vtk_counts_are_bounded_by_the_file(tmp_path, keyword):
    pts = np.array([0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 1, 1, 1], ">f4").tobytes()
    big = 10**9
    parts = {
        "POINTS": b"POINTS %d float\n" % (big if keyword == "POINTS" else 5) + pts + b"\n",
        "CELLS": b"CELLS 1 %d\n" % (big if keyword == "CELLS" else 5) + np.array([4, 0, 1, 2, 3], ">i4").tobytes() + b"\n",
        "CELL_TYPES": b"CELL_TYPES %d\n" % (big if keyword == "CELL_TYPES" else 1) + np.array([10], ">i4").tobytes() + b"\n",
        "SCALARS": b"POINT_DATA 5\nSCALARS s double %d\nLOOKUP_TABLE default\n" % (big if keyword == "SCALARS" else 1)
                   + np.zeros(5, ">f8").tobytes() + b"\n",
    }
    path = tmp_path / "binary.vtk"
    path.write_bytes(_VTK_HEAD.format(mode="BINARY").encode() + b"".join(parts.values()))
    match = (r"SCALARS 's': a SCALARS array has 1 to 4 components" if keyword == "SCALARS" else
             rf"{keyword} [^:]*: .*values of \d+ bytes are declared, but the file ends")
    with deadline(DEADLINE_S, "read_legacy_vtk"), pytest.raises(ValueError, match=match):
        read_legacy_vtk(path)


# ---------------------------------------------------------------------------------
# 2. Decompression bombs: inflated no further than the header declares
# ---------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def bombs():
    zeros = bytes(BOMB_BYTES)
    return {"zlib": zlib.compress(zeros, 9), "gzip": gzip.compress(zeros, 9)}


def _vti_doc(extent: str, arrays_xml: str, *, whole: str | None = None, compressor: str = "",
             appended: bytes | None = None, pieces: list[tuple[str, str]] | None = None) -> bytes:
    comp = f' compressor="{compressor}"' if compressor else ""
    pieces = pieces if pieces is not None else [(extent, arrays_xml)]
    body = "".join(f'<Piece Extent="{e}"><PointData Scalars="d">{a}</PointData></Piece>' for e, a in pieces)
    out = (f'<?xml version="1.0"?>\n<VTKFile type="ImageData" version="1.0" byte_order="LittleEndian" '
           f'header_type="UInt32"{comp}><ImageData WholeExtent="{whole or extent}" Origin="0 0 0" '
           f'Spacing="1 1 1">{body}</ImageData>').encode()
    if appended is not None:
        out += b'<AppendedData encoding="raw">_' + appended + b"</AppendedData>"
    return out + b"</VTKFile>"


def _bomb_file(tmp_path: Path, kind: str, bombs: dict[str, bytes]) -> Path:
    if kind == "nrrd-gzip":
        path = tmp_path / "bomb.nrrd"
        path.write_bytes(b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: gzip\n\n" + bombs["gzip"])
    elif kind == "metaimage-zlib":
        path = tmp_path / "bomb.mha"
        path.write_bytes(b"NDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\nCompressedData = True\n"
                         b"ElementDataFile = LOCAL\n" + bombs["zlib"])
    else:  # the header honestly says 8 bytes in one block; the block inflates to 32 MiB
        path = tmp_path / "bomb.vti"
        head = struct.pack("<4I", 1, 8, 8, len(bombs["zlib"]))
        xml = '<DataArray type="UInt8" Name="d" format="appended" offset="0"/>'
        path.write_bytes(_vti_doc("0 1 0 1 0 1", xml, compressor="vtkZLibDataCompressor",
                                  appended=head + bombs["zlib"]))
    return path


@pytest.mark.parametrize("kind", ["nrrd-gzip", "metaimage-zlib", "vti-zlib"])
def test_decompression_bomb_stops_at_the_declared_size(tmp_path, bombs, kind):
    path = _bomb_file(tmp_path, kind, bombs)
    tracemalloc.start()
    try:
        with deadline(DEADLINE_S, kind), pytest.raises(ValueError, match="inflate to more than the 8 bytes") as info:
            read_volume(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert path.name in str(info.value)
    assert peak < BOMB_PEAK_LIMIT, f"reading a 2x2x2 {kind} bomb peaked at {peak / 2**20:.1f} MiB"


def test_vti_compression_header_larger_than_the_extent(tmp_path, bombs):
    # The header claims 4 GiB for a 2x2x2 piece: refused before a byte is inflated.
    head = struct.pack("<4I", 1, 2**32 - 1, 0, len(bombs["zlib"]))
    xml = ('<DataArray type="UInt8" Name="d" format="binary">'
           + base64.b64encode(head).decode() + base64.b64encode(bombs["zlib"]).decode() + "</DataArray>")
    path = tmp_path / "claims.vti"
    path.write_bytes(_vti_doc("0 1 0 1 0 1", xml, compressor="vtkZLibDataCompressor"))
    with deadline(DEADLINE_S, "read_vti"), pytest.raises(
            ValueError, match=r"claims\.vti.*compression header declares 4294967295 bytes .* extent needs 8"):
        read_vti(path)


def test_gzip_nrrd_declaring_more_than_deflate_can_hold(tmp_path):
    path = tmp_path / "small.nrrd"
    path.write_bytes(b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 400 400 400\nencoding: gzip\n\n"
                     + gzip.compress(bytes(64)))
    with deadline(DEADLINE_S, "read_nrrd"), pytest.raises(
            ValueError, match=r"small\.nrrd.*400 x 400 x 400 voxels of uint8 .*can hold at most"):
        read_nrrd(path)


# ---------------------------------------------------------------------------------
# 3. A pattern of a billion data file names is counted before one is built
# ---------------------------------------------------------------------------------


@pytest.mark.parametrize("fmt", ["nrrd", "metaimage"])
def test_data_file_pattern_is_counted_before_names_are_built(tmp_path, fmt):
    for k in range(2):
        (tmp_path / f"s{k:09d}.raw").write_bytes(bytes([k]) * 4)
    if fmt == "nrrd":
        path = tmp_path / "v.nhdr"
        head = "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: raw\ndata file: s%09d.raw 0 {} 1\n"
        match = r"NRRD file 'v\.nhdr': field 'data file' names 1000000001 files .* need 2"
    else:
        path = tmp_path / "v.mhd"
        head = "NDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\nElementDataFile = s%09d.raw 0 {} 1\n"
        match = r"MetaImage file 'v\.mhd': field 'ElementDataFile' names 1000000001 files .* need 2"
    path.write_text(head.format(1000000000))
    with deadline(2.0, f"{fmt} pattern"), pytest.raises(ValueError, match=match):
        read_volume(path)
    path.write_text(head.format(1))  # the count the sizes need: read as before
    assert read_volume(path).data[:, 0, 0].tolist() == [0, 1]


# ---------------------------------------------------------------------------------
# 4. An Exodus (netCDF) header declaring 3e8 nodes in a 4 KB file
# ---------------------------------------------------------------------------------


def _netcdf_classic(dims: dict[str, int], variables: dict[str, tuple[str, ...]]) -> bytes:
    """A netCDF-3 (64-bit offset) header with double variables and no data."""
    def name(s: str) -> bytes:
        b = s.encode()
        return struct.pack(">i", len(b)) + b + b"\0" * (-len(b) % 4)

    ids = {d: i for i, d in enumerate(dims)}
    out = b"CDF\x02" + struct.pack(">i", 0)
    out += struct.pack(">ii", 0x0A, len(dims)) + b"".join(name(d) + struct.pack(">i", n) for d, n in dims.items())
    out += struct.pack(">ii", 0, 0)  # no global attributes
    out += struct.pack(">ii", 0x0B, len(variables))
    for v, vd in variables.items():
        out += name(v) + struct.pack(">i", len(vd)) + b"".join(struct.pack(">i", ids[d]) for d in vd)
        out += struct.pack(">ii", 0, 0) + struct.pack(">iI", 6, 0xFFFFFFFF) + struct.pack(">q", 4096)
    return out.ljust(4096, b"\0")


def test_exodus_declaring_more_nodes_than_the_file_holds(tmp_path):
    path = tmp_path / "nodes.exo"
    path.write_bytes(_netcdf_classic({"num_nodes": 300_000_000, "num_dim": 3},
                                     {"coordx": ("num_nodes",), "coordy": ("num_nodes",), "coordz": ("num_nodes",)}))
    assert path.stat().st_size == 4096
    with deadline(10.0, "read exodus"), pytest.raises(
            ValueError, match=r"nodes\.exo.*declares 7200000000 bytes of data \(variable 'coordx' of shape "
                              r"\(300000000,\)\), but the file holds 4096 bytes"):
        _quiet_read(path)


# ---------------------------------------------------------------------------------
# 5. fuse(mode="cutaway", margin=10**6) returns promptly
# ---------------------------------------------------------------------------------


def test_cutaway_with_a_huge_margin_is_prompt_and_exact():
    h = w = 128
    mesh_img = np.zeros((h, w, 4), np.float32)
    front = np.full((h, w), np.inf, np.float32)
    back = np.full((h, w), -np.inf, np.float32)
    front[60:64, 70:72], back[60:64, 70:72] = 2.0, 3.0
    back[61, 70] = 5.0
    limits = []

    def volume(t0, t1, mode):
        limits.append(t0)
        return np.zeros((h, w, 4), np.float32)

    with deadline(DEADLINE_S, "cutaway margin=10**6"):
        compose("cutaway", mesh_img, front, back, volume, margin=10**6)
    compose("cutaway", mesh_img, front, back, volume, margin=w - 1)
    assert np.array_equal(limits[0], limits[1])  # a margin past the image is one across it
    assert np.all(limits[0] == 5.0)  # the farthest exit reaches every pixel


# ---------------------------------------------------------------------------------
# 6. VTI pieces must cover the whole extent; a piece extent is 6 integers
# ---------------------------------------------------------------------------------


def _ascii(values) -> str:
    return '<DataArray type="UInt8" Name="d" format="ascii">' + " ".join(map(str, values)) + "</DataArray>"


def test_vti_pieces_leaving_part_of_the_extent_uncovered(tmp_path):
    path = tmp_path / "gap.vti"
    path.write_bytes(_vti_doc("", "", whole="0 5 0 1 0 1",
                              pieces=[("0 1 0 1 0 1", _ascii(range(8))), ("4 5 0 1 0 1", _ascii(range(8)))]))
    with deadline(DEADLINE_S, "read_vti"), pytest.raises(
            ValueError, match=r"gap\.vti.*WholeExtent 0 5 0 1 0 1 uncovered: 8 points within extent 2 3 0 1 0 1"):
        read_vti(path)
    # Pieces may share their boundary points; covering the extent together, they read.
    path.write_bytes(_vti_doc("", "", whole="0 2 0 0 0 0",
                              pieces=[("0 1 0 0 0 0", _ascii([1, 2])), ("1 2 0 0 0 0", _ascii([2, 3]))]))
    assert read_vti(path).data.ravel().tolist() == [1, 2, 3]


@pytest.mark.parametrize("extent", ["0 1 0 1", "0 1 0 1 0 x", "1 0 0 1 0 1"])
def test_vti_piece_extent_that_is_not_six_ordered_integers(tmp_path, extent):
    path = tmp_path / "ext.vti"
    path.write_bytes(_vti_doc("", "", whole="0 1 0 1 0 1", pieces=[(extent, _ascii(range(8)))]))
    with pytest.raises(ValueError, match=r"ext\.vti.*Piece 0 Extent"):
        read_vti(path)


# ---------------------------------------------------------------------------------
# 7. DICOM rescale: non-finite refused, large values never wrap
# ---------------------------------------------------------------------------------


def _dicom_slice(folder: Path, pixels: np.ndarray, slope: str, intercept: str = "0") -> Path:
    pytest.importorskip("pydicom")
    from pydicom.dataset import Dataset, FileMetaDataset
    from pydicom.uid import ExplicitVRLittleEndian, generate_uid

    meta = FileMetaDataset()
    meta.MediaStorageSOPClassUID = "1.2.840.10008.5.1.4.1.1.2"
    meta.MediaStorageSOPInstanceUID = generate_uid()
    meta.TransferSyntaxUID = ExplicitVRLittleEndian
    ds = Dataset()
    ds.file_meta = meta
    ds.SOPClassUID, ds.SOPInstanceUID = meta.MediaStorageSOPClassUID, meta.MediaStorageSOPInstanceUID
    ds.Modality, ds.SeriesInstanceUID = "CT", "1.2.3"
    ds.ImageOrientationPatient = [1, 0, 0, 0, 1, 0]
    ds.ImagePositionPatient = [0, 0, 0]
    ds.PixelSpacing = [1, 1]
    ds.Rows, ds.Columns = pixels.shape
    ds.SamplesPerPixel, ds.PhotometricInterpretation = 1, "MONOCHROME2"
    ds.BitsAllocated = ds.BitsStored = 16
    ds.HighBit, ds.PixelRepresentation = 15, 0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # pydicom warns about 'inf' as a DS value, and writes it
        ds.RescaleSlope, ds.RescaleIntercept = slope, intercept
        ds.PixelData = pixels.astype("<u2").tobytes()
        path = folder / "slice.dcm"
        ds.save_as(path, enforce_file_format=True)
    return path


@pytest.mark.parametrize("slope,intercept,bad", [("inf", "0", "RescaleSlope"), ("nan", "0", "RescaleSlope"),
                                                 ("1", "-inf", "RescaleIntercept"), ("0", "0", "RescaleSlope")])
def test_dicom_non_finite_rescale_is_refused(tmp_path, slope, intercept, bad):
    path = _dicom_slice(tmp_path, np.arange(6).reshape(2, 3), slope, intercept)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(ValueError, match=rf"slice\.dcm.*{bad} must be a finite"):
            read_dicom(path)


@pytest.mark.parametrize("slope", ["1e30", "4611686018427387904"])  # 2**62: integral, wraps int64 at x2
def test_dicom_rescale_beyond_int64_does_not_wrap(tmp_path, slope):
    raw = np.array([[0, 1, 2], [3, 1000, 65535]])
    path = _dicom_slice(tmp_path, raw, slope, "-1024")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        vol = read_dicom(path)
    want = raw.astype(np.float64) * float(slope) - 1024
    assert vol.data.dtype.kind == "f"
    np.testing.assert_allclose(vol.data[0], want, rtol=1e-6)
    assert vol.data.min() >= -1024


def test_dicom_declaring_more_pixels_than_the_file_holds(tmp_path):
    pydicom = pytest.importorskip("pydicom")
    path = _dicom_slice(tmp_path, np.arange(6).reshape(2, 3), "1")
    ds = pydicom.dcmread(path)
    ds.Rows = ds.Columns = 30000  # 1.7 GiB declared over 12 bytes of pixel data
    ds.save_as(path)
    with deadline(DEADLINE_S, "read_dicom"), pytest.raises(
            ValueError, match=r"slice\.dcm.*declares 30000 x 30000 x 1 voxels of uint16 .*can hold at most"):
        read_dicom(path)


# ---------------------------------------------------------------------------------
# 8. NIfTI, VTI and legacy structured points declaring more than memory or the file
# ---------------------------------------------------------------------------------


def test_nifti_that_is_not_gzip_names_the_file(tmp_path):
    pytest.importorskip("nibabel")
    path = tmp_path / "fake.nii.gz"
    path.write_bytes(b"this is not gzip data " * 30)
    with pytest.raises(ValueError, match=r"cannot read NIfTI file 'fake\.nii\.gz'.*not a gzip file"):
        read_nifti(path)


def test_nifti_declaring_30000_cubed(tmp_path):
    nib = pytest.importorskip("nibabel")
    path = tmp_path / "huge.nii"
    nib.save(nib.Nifti1Image(np.zeros((2, 2, 2), np.int16), np.eye(4)), path)
    raw = bytearray(path.read_bytes())
    raw[40:48] = struct.pack("<4h", 3, 30000, 30000, 30000)  # dim[0..3] of the NIfTI-1 header
    path.write_bytes(bytes(raw))
    with deadline(DEADLINE_S, "read_nifti"), pytest.raises(
            ValueError, match=r"huge\.nii.*declares 30000 x 30000 x 30000 voxels of int16"):
        read_nifti(path)


def test_vti_whole_extent_of_3000_cubed(tmp_path):
    path = tmp_path / "whole.vti"
    xml = '<DataArray type="Float64" Name="d" format="ascii">' + " 0" * 8 + "</DataArray>"
    path.write_bytes(_vti_doc("", "", whole="0 2999 0 2999 0 2999", pieces=[("0 1 0 1 0 1", xml)]))
    with deadline(DEADLINE_S, "read_vti"), pytest.raises(
            ValueError, match=r"whole\.vti.*declares 3000 x 3000 x 3000 voxels of float64 .*memory"):
        read_vti(path)


@pytest.mark.parametrize("mode", ["ASCII", "BINARY"])
def test_structured_points_declaring_1e15_points(tmp_path, mode):
    path = tmp_path / "huge.vtk"
    path.write_text(f"# vtk DataFile Version 3.0\nx\n{mode}\nDATASET STRUCTURED_POINTS\n"
                    "DIMENSIONS 100000 100000 100000\nPOINT_DATA 1000000000000000\n"
                    "SCALARS s float 1\nLOOKUP_TABLE default\n0 0 0\n")
    with deadline(DEADLINE_S, "read structured points"), pytest.raises(
            ValueError, match=r"huge\.vtk.*DIMENSIONS \(100000, 100000, 100000\).* 1000000000000000 points"):
        read_volume(path)


# ---------------------------------------------------------------------------------
# 9. Paths that are not plain files are reported as what they are
# ---------------------------------------------------------------------------------


def _special_path(tmp_path: Path, kind: str, suffix: str) -> Path:
    if kind == "symlink-loop":
        os.symlink(f"b{suffix}", tmp_path / f"a{suffix}")
        os.symlink(f"a{suffix}", tmp_path / f"b{suffix}")
        return tmp_path / f"a{suffix}"
    if kind == "name-300-characters":
        return tmp_path / ("n" * (300 - len(suffix)) + suffix)
    if kind == "path-beyond-path-max":
        return tmp_path.joinpath(*["d" * 200] * 25, "m" + suffix)
    path = tmp_path / f"pipe{suffix}"
    os.mkfifo(path)  # never opened: reading it would block until a writer comes
    return path


SPECIAL = [("symlink-loop", "symbolic links form a loop"), ("name-300-characters", "file name is too long"),
           ("path-beyond-path-max", "path is too long"), ("fifo", "a FIFO .*not a regular file")]


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="POSIX paths")
@pytest.mark.parametrize("kind,match", SPECIAL, ids=[s[0] for s in SPECIAL])
@pytest.mark.parametrize("reader,suffix", [(tetvr.read, ".vtu"), (read_volume, ".nrrd"), (read_nrrd, ".nhdr")],
                         ids=["mesh", "volume", "nrrd"])
def test_special_paths_are_reported_truthfully(tmp_path, kind, match, reader, suffix):
    path = _special_path(tmp_path, kind, suffix)
    with deadline(DEADLINE_S, f"{reader.__name__}({kind})"), pytest.raises(ValueError, match=match) as info:
        reader(path)
    assert "not found" not in str(info.value) and "empty" not in str(info.value)


def test_dangling_symlink_is_not_found_and_says_where_it_points(tmp_path):
    os.symlink("gone.vtu", tmp_path / "link.vtu")
    with pytest.raises(FileNotFoundError, match=r"link\.vtu' is a symbolic link to 'gone\.vtu', which does not exist"):
        tetvr.read(tmp_path / "link.vtu")


def test_detached_data_file_that_is_a_fifo(tmp_path):
    os.mkfifo(tmp_path / "data.raw")
    (tmp_path / "v.nhdr").write_text("NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n"
                                     "data file: data.raw\n")
    with deadline(DEADLINE_S, "FIFO data file"), pytest.raises(
            ValueError, match=r"NRRD data file .*data\.raw' \(named by 'v\.nhdr'\): it is a FIFO"):
        read_nrrd(tmp_path / "v.nhdr")


# ---------------------------------------------------------------------------------
# 10. Vertex ids of inf or 1e20; fields of the wrong length
# ---------------------------------------------------------------------------------


@pytest.mark.parametrize("bad,exc,match", [(np.inf, TypeError, r"holding inf \(tet 1: \[1\.0, 2\.0, 3\.0, inf\]\)"),
                                           (-np.inf, TypeError, "holding -inf"),
                                           (1e20, ValueError, r"tets index point 1e\+20, outside 0\.\.4")])
def test_tet_ids_of_inf_or_1e20_are_named(bad, exc, match):
    tets = np.array([[0, 1, 2, 3], [1, 2, 3, bad]], dtype=np.float64)
    with pytest.raises(exc, match=match):
        TetMesh.from_arrays(POINTS, tets, SCALARS)


def _vtu_with_float_ids(tmp_path: Path, last: str) -> Path:
    import meshio

    path = tmp_path / "ids.vtu"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        meshio.write(path, meshio.Mesh(POINTS, [("tetra", np.array([[0, 1, 2, 3]]))], point_data={"s": SCALARS}),
                     binary=False)
    text = path.read_text()
    head, tail = text.split('Name="connectivity"', 1)
    body, rest = tail.split("</DataArray>", 1)
    path.write_text(head.replace('type="Int64"', "").rsplit("<DataArray", 1)[0]
                    + f'<DataArray type="Float64" Name="connectivity" format="ascii">0 1 2 {last}</DataArray>' + rest)
    return path


@pytest.mark.parametrize("last,match", [("inf", r"node id inf in cell 0"), ("1e20", r"indexes point 1e\+20")])
def test_float_vertex_ids_in_a_mesh_file_are_named(tmp_path, last, match):
    path = _vtu_with_float_ids(tmp_path, last)
    with pytest.raises(ValueError, match=rf"ids\.vtu.*{match}|{match}"):
        _quiet_read(path)


_STRIPS = """# vtk DataFile Version 3.0
strips
ASCII
DATASET UNSTRUCTURED_GRID
POINTS 5 float
0 0 0 1 0 0 0 1 0 0 0 1 1 1 1
CELLS 2 9
4 0 1 2 3
3 1 2 4
CELL_TYPES 2
10
6
"""


@pytest.mark.parametrize("data,match", [
    ("POINT_DATA 4\nSCALARS s float 1\nLOOKUP_TABLE default\n0 1 2 3\n", r"POINT_DATA 4 does not match the 5 points"),
    ("CELL_DATA 3\nSCALARS c float 1\nLOOKUP_TABLE default\n0 1 2\n", r"CELL_DATA 3 does not match the 2 cells"),
    ("POINT_DATA 5\nFIELD f 1\nt 1 4 float\n0 1 2 3\n", r"FIELD array 't': 4 tuples in POINT_DATA 5"),
])
def test_legacy_vtk_field_of_the_wrong_length(tmp_path, data, match):
    path = tmp_path / "strips.vtk"  # meshio refuses the strip: the fallback reader reads it
    path.write_text(_STRIPS + data)
    with pytest.raises(ValueError, match=rf"strips\.vtk.*{match}"):
        _quiet_read(path)


@pytest.mark.parametrize("where", ["point", "cell"])
def test_field_of_the_wrong_length_from_any_reader(tmp_path, where):
    (tmp_path / "m.vtu").write_bytes(b"<VTKFile/>")  # the reader below stands in for meshio
    mesh = SimpleNamespace(points=POINTS, cells=[SimpleNamespace(type="tetra", data=np.array([[0, 1, 2, 3]]))],
                           point_data={"s": np.arange(4.0)} if where == "point" else {},
                           cell_data={"c": [np.ones(3)]} if where == "cell" else {})
    match = (r"point field 's' has 4 values \(shape \(4,\)\), but the mesh has 5 points" if where == "point" else
             r"cell field 'c' has 3 values in 1 blocks \[3\], but the mesh has 1 cells")
    with pytest.raises(ValueError, match=match):
        read_cells(tmp_path / "m.vtu", meshio_read=lambda path: mesh)


# ---------------------------------------------------------------------------------
# 11. NRRD and MetaImage header errors name the field and the file
# ---------------------------------------------------------------------------------

HEADER_CASES = [
    ("h.nrrd", "NRRD0004\ntype: uchar\ndimension: three\nsizes: 2 2 2\nencoding: raw\n\n",
     r"NRRD file 'h\.nrrd': field 'dimension' must be an integer, got 'three'"),
    ("h.nrrd", "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2\nencoding: raw\n\n",
     r"NRRD file 'h\.nrrd': field 'sizes' lists 2 values"),
    ("h.nrrd", "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 x 2\nencoding: raw\n\n",
     r"NRRD file 'h\.nrrd': field 'sizes' must be integers, got '2 x 2'"),
    ("h.nrrd", "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: raw\nspacings: 1 one 1\n\n",
     r"NRRD file 'h\.nrrd': field 'spacings' must be numbers"),
    ("h.nrrd", "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: raw\nspace origin: (0,a,0)\n\n",
     r"NRRD file 'h\.nrrd': field 'space origin' must be numbers"),
    ("h.nrrd", "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: raw\nbyte skip: lots\n\n",
     r"NRRD file 'h\.nrrd': field 'byte skip' must be an integer, got 'lots'"),
    ("h.mha", "NDims = three\nDimSize = 2 2 2\nElementType = MET_UCHAR\nElementDataFile = LOCAL\n",
     r"MetaImage file 'h\.mha': field 'NDims' must be an integer, got 'three'"),
    ("h.mha", "NDims = 3\nDimSize = 2 two 2\nElementType = MET_UCHAR\nElementDataFile = LOCAL\n",
     r"MetaImage file 'h\.mha': field 'DimSize' must be integers, got '2 two 2'"),
    ("h.mha", "NDims = 3\nDimSize = 2 2 2\nElementSpacing = 1 1\nElementType = MET_UCHAR\nElementDataFile = LOCAL\n",
     r"MetaImage file 'h\.mha': field 'ElementSpacing' must be 3 finite numbers, got '1 1'"),
    ("h.mha", "NDims = 3\nDimSize = 2 2 2\nHeaderSize = big\nElementType = MET_UCHAR\nElementDataFile = LOCAL\n",
     r"MetaImage file 'h\.mha': field 'HeaderSize' must be an integer, got 'big'"),
    ("h.mha", "NDims = 3\nDimSize = 2 2 2\nElementType = MET_COMPLEX\nElementDataFile = LOCAL\n",
     r"MetaImage file 'h\.mha': field 'ElementType' 'MET_COMPLEX' is not supported"),
]


@pytest.mark.parametrize("name,header,match", HEADER_CASES, ids=[f"{c[0]}-{i}" for i, c in enumerate(HEADER_CASES)])
def test_header_errors_name_the_field_and_the_file(tmp_path, name, header, match):
    path = tmp_path / name
    path.write_bytes(header.encode() + bytes(8))
    with pytest.raises(ValueError, match=match):
        read_volume(path)


# ---- surfaces and folders: what a message says ----

@pytest.mark.parametrize("declared,body", [(2**31, 2), (2**32 - 1, 0), (3, 2)],
                         ids=["2^31-triangles", "uint32-max", "truncated"])
def test_binary_stl_whose_count_lies_is_named_as_such(tmp_path, declared, body):
    """meshio computes 84 + 50 n in uint32 (wrapping) and then reads the file as ASCII:
    a binary STL declaring 2^31 triangles came back as "no triangles"."""
    from tetvr.core.surface import Surface

    path = tmp_path / "part.stl"
    path.write_bytes(b"binary STL".ljust(80, b"\0") + struct.pack("<I", declared) + bytes(50 * body))
    with deadline(DEADLINE_S, "Surface.read"), pytest.raises(
            ValueError, match=rf"surface file '.*part\.stl' is a binary STL that declares {declared} triangles "
                              rf"\({84 + 50 * declared} bytes\) but is {84 + 50 * body} bytes long \({body} whole "
                              r"triangles\): it is truncated or damaged; export it again"):
        Surface.read(path)


def test_good_stl_files_still_read(tmp_path):
    import meshio

    from tetvr.core.surface import Surface

    tri = meshio.Mesh(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float), [("triangle", np.array([[0, 1, 2]]))])
    for binary in (True, False):
        meshio.write(tmp_path / "t.stl", tri, binary=binary)
        with np.errstate(all="raise"):  # meshio's uint32 size test is kept quiet
            assert Surface.read(tmp_path / "t.stl").n_triangles == 1


def test_info_on_a_folder_says_it_is_one_and_what_info_reads(tmp_path, capfd):
    from tetvr.apps.cli import EXIT_USAGE, main

    (tmp_path / "notes.txt").write_text("not an image")
    assert main(["info", str(tmp_path)]) == EXIT_USAGE
    err = capfd.readouterr().err  # the file descriptor: ITK warns in C++
    assert err.count("\n") == 1 and err.startswith("tetvr: error: "), err  # no ITK warning before it
    assert f"'{tmp_path}' is a folder with no DICOM images in it" in err
    assert "tetvr info describes a mesh file" in err and "a folder of DICOM slices" in err
