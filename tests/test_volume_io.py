"""Volume readers: the shared data sets against the README's table, small files written
here byte by byte from the format specifications (so the parsers are checked against
the formats, not against a writer of our own), and bad inputs.

Pure numpy: no OpenGL.
"""

from __future__ import annotations

import base64
import gzip
import struct
import sys
import warnings
import zlib

import numpy as np
import pytest

from tetvr.volume.volume import Volume
from tetvr.io.volume_file import read_dicom, read_metaimage, read_nifti, read_nrrd, read_raw, read_volume, read_vti, read_vtk_structured_points

from .conftest import SHARED, shared_file


@pytest.fixture(autouse=True)
def _strict_numpy():
    with np.errstate(all="raise"):
        yield


def _rotation(a: float, b: float) -> np.ndarray:
    ca, sa, cb, sb = np.cos(a), np.sin(a), np.cos(b), np.sin(b)
    rz = np.array([[ca, -sa, 0], [sa, ca, 0], [0, 0, 1]])
    rx = np.array([[1, 0, 0], [0, cb, -sb], [0, sb, cb]])
    return rz @ rx


def _ramp(shape=(3, 4, 5), dtype=np.int16) -> np.ndarray:
    """(nz, ny, nx) values that differ at every voxel and reveal any axis mix-up."""
    nz, ny, nx = shape
    k, j, i = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
    return (i + 10 * j + 100 * k - 7).astype(dtype)


# ---------------------------------------------------------------------------------
# The shared data (README table)
# ---------------------------------------------------------------------------------

# file, dims (nx, ny, nz), spacing, dtype, value range, needs
SHARED_VOLUMES = [
    ("volumes/headsq/quarter.nhdr", (64, 64, 93), (3.2, 3.2, 1.5), "int16", (0, 3926), "SimpleITK"),
    ("volumes/HeadMRVolume.mhd", (48, 62, 42), (4.0, 4.0, 4.0), "uint8", (0, 255), "SimpleITK"),
    ("volumes/LIDC2.mha", (256, 256, 133), (1.40625, 1.40625, 2.5), "uint8", (0, 255), "SimpleITK"),
    ("volumes/aneurism.vti", (256, 256, 256), (1.0, 1.0, 1.0), "uint8", (0, 255), None),
    ("volumes/hydrogen.vti", (64, 64, 64), (1.0, 1.0, 1.0), "float32", (0, 1), None),
    ("volumes/carotid.vtk", (76, 49, 45), (1.0, 1.0, 1.0), "float32", (0, 580), None),
    ("volumes/avg152T1_RL_nifti.nii.gz", (91, 109, 91), (2.0, 2.0, 2.0), "uint8", (0, 255), "SimpleITK"),
    ("volumes/CT_small.dcm", (128, 128, 1), (0.661468, 0.661468, 5.0), "int16", (-896, 1167), "SimpleITK"),
]


@pytest.mark.data
@pytest.mark.parametrize("rel,dims,spacing,dtype,value_range,needs", SHARED_VOLUMES,
                         ids=[row[0].split("/")[-1] for row in SHARED_VOLUMES])
def test_shared_volume_matches_readme(rel, dims, spacing, dtype, value_range, needs):
    path = shared_file(rel)
    if needs:
        pytest.importorskip(needs, reason=f"{needs} (optional extra tetvr[volumes]) is not installed")
    vol = read_volume(path)
    assert vol.dims == dims
    np.testing.assert_allclose(vol.spacing, spacing, rtol=1e-5)
    assert vol.dtype == np.dtype(dtype)
    lo, hi = vol.scalar_range
    assert (lo, hi) == pytest.approx(value_range, abs=1e-6)
    assert not vol.data.flags.writeable


@pytest.mark.data
def test_headsq_slices_are_stacked_in_file_order():
    path = shared_file("volumes/headsq/quarter.nhdr")
    vol = read_nrrd(path)
    first = np.fromfile(path.parent / "quarter.1", dtype="<i2").reshape(64, 64)
    last = np.fromfile(path.parent / "quarter.93", dtype="<i2").reshape(64, 64)
    np.testing.assert_array_equal(vol.data[0], first)
    np.testing.assert_array_equal(vol.data[-1], last)
    assert vol.space == ""  # "3D-left-handed" is not an anatomical frame


@pytest.mark.data
def test_lidc_direction_matrix_is_honoured():
    vol = read_volume(shared_file("volumes/LIDC2.mha"))
    # TransformMatrix "1 0 0  0 -1 0  0 0 -1": y and z index axes run against world y, z.
    np.testing.assert_allclose(vol.direction, np.diag([1.0, -1.0, -1.0]), atol=1e-12)
    np.testing.assert_allclose(vol.origin, [0.0, 360.0, 332.5], atol=1e-9)
    last = vol.index_to_world @ [255, 255, 132, 1]
    np.testing.assert_allclose(last[:3], [255 * 1.40625, 360 - 255 * 1.40625, 332.5 - 132 * 2.5], atol=1e-6)
    assert vol.space == "LPS"


@pytest.mark.data
def test_nifti_affine_is_brought_to_lps_or_kept_in_ras():
    pytest.importorskip("nibabel")
    path = shared_file("volumes/avg152T1_RL_nifti.nii.gz")
    lps = read_volume(path)
    ras = read_volume(path, space="RAS")
    # The file's RAS affine: diag(2, 2, 2), origin (-90, -126, -72).
    np.testing.assert_allclose(ras.index_to_world[:3], [[2, 0, 0, -90], [0, 2, 0, -126], [0, 0, 2, -72]])
    np.testing.assert_allclose(lps.index_to_world[:3], [[-2, 0, 0, 90], [0, -2, 0, 126], [0, 0, 2, -72]])
    np.testing.assert_array_equal(lps.data, ras.data)


@pytest.mark.data
def test_carotid_vectors_can_be_chosen_by_name():
    path = shared_file("volumes/carotid.vtk")
    speed = read_vtk_structured_points(path)
    vel = read_vtk_structured_points(path, scalars="vectors")
    assert speed.scalar_name == "scalars" and vel.scalar_name == "vectors"
    np.testing.assert_allclose(speed.origin, [100, 80, 1])
    assert vel.dims == speed.dims and vel.scalar_range[0] >= 0


# ---------------------------------------------------------------------------------
# Round trips on files written here
# ---------------------------------------------------------------------------------


def test_raw_round_trip_little_and_big_endian(tmp_path):
    data = _ramp(dtype=np.int16)
    (tmp_path / "le.raw").write_bytes(data.astype("<i2").tobytes())
    (tmp_path / "be.raw").write_bytes(b"HEADER" + data.astype(">i2").tobytes())
    le = read_raw(tmp_path / "le.raw", dims=(5, 4, 3), dtype="int16", spacing=(0.5, 1, 2), origin=(1, 2, 3))
    be = read_raw(tmp_path / "be.raw", dims=(5, 4, 3), dtype="int16", byte_order="big", header_bytes=6)
    np.testing.assert_array_equal(le.data, data)
    np.testing.assert_array_equal(be.data, data)
    assert le.dtype == np.int16 and le.data.dtype.byteorder in "=|"
    np.testing.assert_allclose(le.index_to_world @ [4, 3, 2, 1], [1 + 2.0, 2 + 3.0, 3 + 4.0, 1])


def test_nrrd_attached_raw_and_gzip(tmp_path):
    data = _ramp(dtype=np.uint16)
    header = ("NRRD0004\ntype: unsigned short\ndimension: 3\nsizes: 5 4 3\nendian: big\n"
              "spacings: 0.5 0.25 2\n# a comment\nkey:=value with: colon\nencoding: {enc}\n\n")
    (tmp_path / "raw.nrrd").write_bytes(header.format(enc="raw").encode() + data.astype(">u2").tobytes())
    (tmp_path / "gz.nrrd").write_bytes(header.format(enc="gzip").encode() + gzip.compress(data.astype(">u2").tobytes()))
    for name in ("raw.nrrd", "gz.nrrd"):
        vol = read_volume(tmp_path / name)
        np.testing.assert_array_equal(vol.data, data)
        np.testing.assert_allclose(vol.spacing, [0.5, 0.25, 2])
        assert vol.dtype == np.uint16


def test_nrrd_detached_slices_with_space_directions_in_ras(tmp_path):
    data = _ramp(dtype=np.float32) * 0.5
    for k in range(3):
        (tmp_path / f"slice{k:03d}.raw").write_bytes(data[k].astype("<f4").tobytes())
    d = np.array([[0, 0.5, 0], [-0.25, 0, 0], [0, 0, 2.0]])  # rows: axis vectors
    dirs = " ".join(f"({a},{b},{c})" for a, b, c in d)
    (tmp_path / "vol.nhdr").write_text(
        "NRRD0005\ntype: float\ndimension: 3\nsizes: 5 4 3\nendian: little\nencoding: raw\n"
        f"space: right-anterior-superior\nspace directions: {dirs}\nspace origin: (10,20,30)\n"
        "data file: slice%03d.raw 0 2 1\n")
    ras = read_nrrd(tmp_path / "vol.nhdr", space="RAS")
    lps = read_nrrd(tmp_path / "vol.nhdr")
    np.testing.assert_array_equal(ras.data, data)
    np.testing.assert_allclose(ras.spacing, [0.5, 0.25, 2.0])
    # index (i, j, k) -> origin + i*d0 + j*d1 + k*d2 (RAS), then x, y flipped for LPS.
    want = np.array([10, 20, 30]) + 4 * d[0] + 3 * d[1] + 2 * d[2]
    np.testing.assert_allclose((ras.index_to_world @ [4, 3, 2, 1])[:3], want)
    np.testing.assert_allclose((lps.index_to_world @ [4, 3, 2, 1])[:3], want * [-1, -1, 1])
    assert (ras.space, lps.space) == ("RAS", "LPS")


def test_nrrd_ascii_and_list_of_files(tmp_path):
    data = _ramp(dtype=np.int32)
    # One file per slice (teem, the NRRD reference reader, wants one per slab of the last axis).
    (tmp_path / "a.txt").write_text(" ".join(str(v) for v in data[0].ravel()))
    (tmp_path / "b.txt").write_text("\n".join(str(v) for v in data[1].ravel()))
    (tmp_path / "c.txt").write_text("\n".join(" ".join(str(v) for v in row) for row in data[2]))
    (tmp_path / "v.nhdr").write_text("NRRD0004\ntype: int\ndimension: 3\nsizes: 5 4 3\nencoding: ascii\n"
                                     "data file: LIST\na.txt\nb.txt\nc.txt\n")
    vol = read_nrrd(tmp_path / "v.nhdr")
    np.testing.assert_array_equal(vol.data, data)
    assert vol.dtype == np.int32


@pytest.mark.parametrize("local,compressed", [(True, False), (False, False), (True, True)])
def test_metaimage_with_direction_matrix(tmp_path, local, compressed):
    data = _ramp(dtype=np.int16)
    rot = _rotation(0.4, -0.3)  # columns: directions of the index axes
    payload = data.astype("<i2").tobytes()
    if compressed:
        payload = zlib.compress(payload)
    # ITK's MetaImageIO: the a-th triple of TransformMatrix is the direction of index axis a.
    tm = " ".join(f"{v:.17g}" for v in rot.T.ravel())
    head = (f"ObjectType = Image\nNDims = 3\nBinaryData = True\nBinaryDataByteOrderMSB = False\n"
            f"CompressedData = {compressed}\nTransformMatrix = {tm}\nOffset = -5 6.5 7\n"
            f"AnatomicalOrientation = RAI\nElementSpacing = 0.7 0.8 1.5\nDimSize = 5 4 3\n"
            f"ElementType = MET_SHORT\n")
    if local:
        (tmp_path / "v.mha").write_bytes((head + "ElementDataFile = LOCAL\n").encode() + payload)
        path = tmp_path / "v.mha"
    else:
        (tmp_path / "v.raw").write_bytes(payload)
        (tmp_path / "v.mhd").write_text(head + "ElementDataFile = v.raw\n")
        path = tmp_path / "v.mhd"
    vol = read_metaimage(path)
    np.testing.assert_array_equal(vol.data, data)
    np.testing.assert_allclose(vol.direction, rot, atol=1e-12)
    ijk = np.array([4.0, 1.0, 2.0])
    want = np.array([-5, 6.5, 7]) + rot @ (ijk * [0.7, 0.8, 1.5])
    np.testing.assert_allclose((vol.index_to_world @ np.r_[ijk, 1])[:3], want, atol=1e-12)
    np.testing.assert_allclose(vol.world_to_index @ np.r_[want, 1], np.r_[ijk, 1], atol=1e-12)
    assert vol.space == "LPS"


def _vti(array_xml: str, appended: bytes | None = None, *, header_type="UInt32", compressor="", encoding="raw",
         extent=(0, 4, 0, 3, 0, 2), direction="1 0 0 0 1 0 0 0 1") -> bytes:
    ext = " ".join(str(v) for v in extent)
    comp = f' compressor="{compressor}"' if compressor else ""
    text = (f'<?xml version="1.0"?>\n<VTKFile type="ImageData" version="1.0" byte_order="LittleEndian" '
            f'header_type="{header_type}"{comp}>\n'
            f'  <ImageData WholeExtent="{ext}" Origin="1 2 3" Spacing="0.5 0.5 2" Direction="{direction}">\n'
            f'  <Piece Extent="{ext}">\n    <PointData Scalars="density">\n{array_xml}\n    </PointData>\n'
            f'  </Piece>\n  </ImageData>\n')
    out = text.encode()
    if appended is not None:
        out += f'  <AppendedData encoding="{encoding}">\n   _'.encode() + appended + b"\n  </AppendedData>\n"
    return out + b"</VTKFile>\n"


def test_vti_ascii_binary_compressed_and_appended(tmp_path):
    data = _ramp(dtype=np.float32) * 0.25
    raw = data.astype("<f4").tobytes()
    other = '      <DataArray type="Int32" Name="other" format="ascii">' + " 0" * 60 + "</DataArray>\n"
    ascii_xml = other + ('      <DataArray type="Float32" Name="density" format="ascii">'
                         + " ".join(repr(float(v)) for v in data.ravel()) + "</DataArray>")
    # Uncompressed binary: header and data in one base64 stream.
    b64 = base64.b64encode(struct.pack("<I", len(raw)) + raw).decode()
    binary_xml = f'      <DataArray type="Float32" Name="density" format="binary">{b64}</DataArray>'
    # zlib, two blocks: the header is encoded on its own, then the blocks.
    blocks = [raw[:32], raw[32:]]
    comp = [zlib.compress(b) for b in blocks]
    header = struct.pack("<4I", 2, 32, len(blocks[-1]), len(comp[0])) + struct.pack("<I", len(comp[1]))
    zxml = (f'      <DataArray type="Float32" Name="density" format="binary">'
            f'{base64.b64encode(header).decode()}{base64.b64encode(b"".join(comp)).decode()}</DataArray>')
    # Appended raw with a UInt64 header, after another array.
    junk = struct.pack("<Q", 4) + b"\x00\x01\x02\x03"
    appended = junk + struct.pack("<Q", len(raw)) + raw
    app_xml = (f'      <DataArray type="UInt8" Name="junk" format="appended" offset="0"/>\n'
               f'      <DataArray type="Float32" Name="density" format="appended" offset="{len(junk)}"/>')
    # Appended base64: each array is its own base64 stream; offsets count characters.
    enc = [base64.b64encode(struct.pack("<I", 4) + b"\x00\x01\x02\x03"), base64.b64encode(struct.pack("<I", len(raw)) + raw)]
    app64_xml = (f'      <DataArray type="UInt8" Name="junk" format="appended" offset="0"/>\n'
                 f'      <DataArray type="Float32" Name="density" format="appended" offset="{len(enc[0])}"/>')
    files = {
        "ascii.vti": _vti(ascii_xml),
        "appended64.vti": _vti(app64_xml, enc[0] + enc[1], encoding="base64"),
        "binary.vti": _vti(binary_xml),
        "zlib.vti": _vti(zxml, compressor="vtkZLibDataCompressor"),
        "appended.vti": _vti(app_xml, appended, header_type="UInt64"),
    }
    for name, content in files.items():
        (tmp_path / name).write_bytes(content)
        vol = read_vti(tmp_path / name)
        np.testing.assert_array_equal(vol.data, data, err_msg=name)
        np.testing.assert_allclose(vol.spacing, [0.5, 0.5, 2])
        np.testing.assert_allclose(vol.origin, [1, 2, 3])
        assert vol.scalar_name == "density"
    assert read_vti(tmp_path / "ascii.vti", scalars="other").scalar_range == (0.0, 0.0)


def test_vti_extent_offset_and_direction(tmp_path):
    data = _ramp(dtype=np.uint8)
    rot = _rotation(-0.6, 0.2)
    xml = ('      <DataArray type="UInt8" Name="density" format="ascii">'
           + " ".join(str(v) for v in data.ravel()) + "</DataArray>")
    (tmp_path / "v.vti").write_bytes(_vti(xml, extent=(2, 6, 0, 3, -1, 1), direction=" ".join(map(str, rot.ravel()))))
    vol = read_vti(tmp_path / "v.vti")
    np.testing.assert_array_equal(vol.data, data)
    # vtkImageData: x = origin + D (ijk * spacing), D row-major in the file, ijk in the extent.
    want = np.array([1, 2, 3]) + rot @ (np.array([2 + 4, 0 + 3, -1 + 2]) * [0.5, 0.5, 2])
    np.testing.assert_allclose((vol.index_to_world @ [4, 3, 2, 1])[:3], want, atol=1e-12)


@pytest.mark.parametrize("binary", [False, True])
def test_legacy_vtk_structured_points(tmp_path, binary):
    data = _ramp(dtype=np.float32) * 0.5
    vec = np.stack([data, 2 * data, 0 * data], axis=-1)
    n = data.size
    head = (f"# vtk DataFile Version 3.0\ntest\n{'BINARY' if binary else 'ASCII'}\nDATASET STRUCTURED_POINTS\n"
            f"DIMENSIONS 5 4 3\nSPACING 0.5 1 2\nORIGIN -1 0 1\nPOINT_DATA {n}\n").encode()

    def block(arr, dtype):
        if binary:
            return np.asarray(arr, dtype=dtype).astype(np.dtype(dtype).newbyteorder(">")).tobytes() + b"\n"
        return (" ".join(repr(float(v)) for v in np.ravel(arr)) + "\n").encode()

    body = b"VECTORS velocity float\n" + block(vec, "f4")
    body += b"SCALARS density float 1\nLOOKUP_TABLE default\n" + block(data, "f4")
    body += b"FIELD FieldData 1\nlabels 1 %d int\n" % n + block(np.arange(n), "i4")
    (tmp_path / "v.vtk").write_bytes(head + body)
    vol = read_volume(tmp_path / "v.vtk")
    np.testing.assert_array_equal(vol.data, data)
    np.testing.assert_allclose(vol.spacing, [0.5, 1, 2])
    np.testing.assert_allclose(vol.origin, [-1, 0, 1])
    speed = read_vtk_structured_points(tmp_path / "v.vtk", scalars="velocity")
    np.testing.assert_allclose(speed.data, np.sqrt(5) * np.abs(data), rtol=1e-6)
    labels = read_vtk_structured_points(tmp_path / "v.vtk", scalars="labels")
    np.testing.assert_array_equal(labels.data.ravel(), np.arange(n))


def test_nifti_round_trip_with_oblique_affine(tmp_path):
    nib = pytest.importorskip("nibabel")
    data = _ramp(dtype=np.int16)  # (nz, ny, nx)
    aff = np.eye(4)
    aff[:3, :3] = _rotation(0.3, 0.5) * [1.5, 1.0, 2.5]
    aff[:3, 3] = [-20, 15, 4]
    nib.save(nib.Nifti1Image(data.transpose(2, 1, 0), aff), tmp_path / "v.nii.gz")
    ras = read_nifti(tmp_path / "v.nii.gz", space="RAS")
    lps = read_volume(tmp_path / "v.nii.gz")
    np.testing.assert_array_equal(ras.data, data)
    assert ras.dtype == np.int16
    np.testing.assert_allclose(ras.index_to_world, aff, atol=1e-5)  # NIfTI stores float32
    np.testing.assert_allclose(lps.index_to_world, np.diag([-1, -1, 1, 1]) @ aff, atol=1e-5)


def _write_dicom_series(folder, data, *, spacing=(0.7, 0.6), dz=2.0, intercept=-1024, series="1.2.3.4"):
    pydicom = pytest.importorskip("pydicom")
    from pydicom.dataset import Dataset, FileMetaDataset
    from pydicom.uid import ExplicitVRLittleEndian, generate_uid

    folder.mkdir(exist_ok=True)
    iop = [0.0, 1.0, 0.0, 0.0, 0.0, -1.0]  # sagittal: rows along y, columns down z
    normal = np.cross(iop[:3], iop[3:])
    order = [2, 0, 3, 1][: data.shape[0]] if data.shape[0] == 4 else list(range(data.shape[0]))
    for k in order:  # written out of order, with names that do not sort by position
        meta = FileMetaDataset()
        meta.MediaStorageSOPClassUID = "1.2.840.10008.5.1.4.1.1.2"
        meta.MediaStorageSOPInstanceUID = generate_uid()
        meta.TransferSyntaxUID = ExplicitVRLittleEndian
        ds = Dataset()
        ds.file_meta = meta
        ds.SOPClassUID = meta.MediaStorageSOPClassUID
        ds.SOPInstanceUID = meta.MediaStorageSOPInstanceUID
        ds.Modality = "CT"
        ds.SeriesInstanceUID = series
        ds.ImageOrientationPatient = iop
        ds.ImagePositionPatient = list(np.array([5.0, -3.0, 40.0]) + k * dz * normal)
        ds.PixelSpacing = list(spacing)
        ds.Rows, ds.Columns = data.shape[1], data.shape[2]
        ds.SamplesPerPixel = 1
        ds.PhotometricInterpretation = "MONOCHROME2"
        ds.BitsAllocated = ds.BitsStored = 16
        ds.HighBit = 15
        ds.PixelRepresentation = 0
        ds.RescaleSlope = 1
        ds.RescaleIntercept = intercept
        ds.PixelData = data[k].astype("<u2").tobytes()
        name = folder / f"IM{(7 * k + 3) % 10}.dcm"
        if hasattr(pydicom.dataset.Dataset, "save_as") and "enforce_file_format" in pydicom.dataset.Dataset.save_as.__code__.co_varnames:
            ds.save_as(name, enforce_file_format=True)
        else:  # pragma: no cover - pydicom < 3
            ds.is_little_endian, ds.is_implicit_VR = True, False
            ds.save_as(name, write_like_original=False)
    (folder / "notes.txt").write_text("not a DICOM file")
    return iop, normal


def test_dicom_series_sorted_by_position_with_rescale(tmp_path):
    raw = (_ramp((4, 3, 5), dtype=np.int32) + 1000).astype(np.uint16)
    iop, normal = _write_dicom_series(tmp_path / "series", raw)
    vol = read_volume(tmp_path / "series")
    assert vol.dims == (5, 3, 4)
    np.testing.assert_array_equal(vol.data, raw.astype(np.int32) - 1024)
    assert vol.dtype == np.int16  # HU fit in 16 bits
    np.testing.assert_allclose(vol.spacing, [0.6, 0.7, 2.0])  # PixelSpacing is (row, column) spacing
    np.testing.assert_allclose(vol.direction, np.stack([iop[:3], iop[3:], normal], axis=1), atol=1e-12)
    np.testing.assert_allclose(vol.origin, [5.0, -3.0, 40.0])


def test_dicom_series_written_by_itk_reads_in_slice_order_whatever_the_file_order(tmp_path):
    sitk = pytest.importorskip("SimpleITK", reason="SimpleITK (pip install tetvr[volumes]) is not installed")
    rng = np.random.default_rng(19)
    data = rng.integers(0, 4000, size=(6, 5, 7)).astype(np.int16)
    data[:, 0, 0] = np.arange(6) * 100  # slice k is recognisable by its first voxel
    iop = (0.0, 1.0, 0.0, 0.0, 0.0, -1.0)  # sagittal: rows along y, columns down z
    normal = np.cross(iop[:3], iop[3:])
    origin = np.array([5.0, -3.0, 40.0])
    names = [f"IM{n:02d}.dcm" for n in rng.permutation(6)]  # file names in shuffled order
    writer = sitk.ImageFileWriter()
    writer.KeepOriginalImageUIDOn()
    for k in rng.permutation(6):  # and written in shuffled order
        img = sitk.GetImageFromArray(data[k])
        img.SetSpacing((0.6, 0.7))
        for tag, value in [("0008|0060", "CT"), ("0020|000d", "1.2.3"), ("0020|000e", "1.2.3.4"),
                           ("0008|0018", f"1.2.3.4.{k + 1}"), ("0020|0013", str(6 - k)),  # InstanceNumber lies
                           ("0020|0037", "\\".join(map(str, iop))),
                           ("0020|0032", "\\".join(f"{v:.6f}" for v in origin + 2.5 * k * normal)),
                           ("0028|0030", "0.7\\0.6")]:
            img.SetMetaData(tag, value)
        writer.SetFileName(str(tmp_path / names[k]))
        writer.Execute(img)
    vol = read_dicom(tmp_path)
    assert vol.dims == (7, 5, 6)
    np.testing.assert_array_equal(vol.data[:, 0, 0], np.arange(6) * 100)
    np.testing.assert_array_equal(vol.data, data)
    np.testing.assert_allclose(vol.spacing, [0.6, 0.7, 2.5], rtol=1e-5)
    np.testing.assert_allclose(vol.direction, np.stack([iop[:3], iop[3:], normal], axis=1), atol=1e-6)
    np.testing.assert_allclose(vol.origin, origin, atol=1e-5)


def test_dicom_duplicate_slice_positions_are_rejected(tmp_path):
    raw = (_ramp((4, 3, 5), dtype=np.int32) + 1000).astype(np.uint16)
    _write_dicom_series(tmp_path / "s", raw)
    _write_dicom_series(tmp_path / "t", raw[:1])  # same series UID, same position as slice 0
    for f in (tmp_path / "t").glob("*.dcm"):
        f.rename(tmp_path / "s" / ("dup" + f.name))
    with pytest.raises(ValueError, match="1 slice.*position of another"):
        read_dicom(tmp_path / "s")


def test_dicom_picks_largest_series_and_warns(tmp_path):
    raw = (_ramp((4, 3, 5), dtype=np.int32) + 1000).astype(np.uint16)
    _write_dicom_series(tmp_path / "s", raw)
    _write_dicom_series(tmp_path / "other", raw[:1], series="9.9")
    for f in (tmp_path / "other").glob("*.dcm"):
        f.rename(tmp_path / "s" / ("x" + f.name))
    with pytest.warns(UserWarning, match="series"):
        vol = read_dicom(tmp_path / "s")
    assert vol.dims == (5, 3, 4)


# ---------------------------------------------------------------------------------
# Volume itself
# ---------------------------------------------------------------------------------


def test_volume_copies_and_freezes_its_data():
    src = _ramp(dtype=np.float64)
    vol = Volume.from_array(src, spacing=(1, 2, 3))
    src[0, 0, 0] = 99.0
    assert vol.data[0, 0, 0] == -7
    with pytest.raises(ValueError):
        vol.data[0, 0, 0] = 1.0


def test_sampling_is_exact_at_voxels_and_trilinear_between():
    data = _ramp(dtype=np.float64)  # linear in i, j, k: trilinear reproduces it exactly
    vol = Volume.from_array(data, spacing=(0.5, 1.0, 2.0), origin=(1, 2, 3), direction=_rotation(0.2, 0.9))
    rng = np.random.default_rng(1)
    ijk = rng.uniform([0, 0, 0], [4, 3, 2], size=(50, 3))
    world = ijk @ vol.index_to_world[:3, :3].T + vol.index_to_world[:3, 3]
    np.testing.assert_allclose(vol.sample(world), ijk[:, 0] + 10 * ijk[:, 1] + 100 * ijk[:, 2] - 7, atol=1e-9)
    assert np.isnan(vol.sample(vol.index_to_world[:3, 3] - 5 * vol.direction[:, 0])).all()
    # The cubic B-spline reproduces linear functions too, away from the clamped edges;
    # it smooths a spike to 8/27 of its height at the voxel (weights 1/6, 4/6, 1/6).
    inner = rng.uniform([1, 1, 1], [3, 2, 1], size=(50, 3))
    np.testing.assert_allclose(vol.sample_index(inner, interpolation="cubic"),
                               inner[:, 0] + 10 * inner[:, 1] + 100 * inner[:, 2] - 7, atol=1e-9)
    spike = Volume.from_array(np.pad(np.ones((1, 1, 1)), 2))
    assert spike.sample_index([2.0, 2.0, 2.0], interpolation="cubic") == pytest.approx((4 / 6) ** 3)
    with pytest.raises(ValueError, match="interpolation"):
        vol.sample_index(inner, interpolation="nearest")


def test_downsampling_keeps_the_box_and_warns():
    data = np.random.default_rng(0).uniform(0, 1000, (20, 17, 33)).astype(np.uint16)
    vol = Volume.from_array(data, spacing=(0.5, 1, 2), origin=(3, 4, 5), direction=_rotation(0.1, 0.2))
    with pytest.warns(UserWarning, match="downsampled"):
        small = vol.fit_size(16)
    assert max(small.dims) <= 16
    np.testing.assert_allclose(small.corners, vol.corners, atol=1e-9)
    assert small.scalar_range[0] >= vol.scalar_range[0] and small.scalar_range[1] <= vol.scalar_range[1]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert vol.fit_size(64) is vol


# ---------------------------------------------------------------------------------
# Bad inputs
# ---------------------------------------------------------------------------------


def test_raw_size_mismatch_names_sizes(tmp_path):
    (tmp_path / "v.raw").write_bytes(b"\x00" * 100)
    with pytest.raises(ValueError, match=r"100 bytes.*\(5, 4, 3\).*int16.*need 120"):
        read_raw(tmp_path / "v.raw", dims=(5, 4, 3), dtype="int16")


@pytest.mark.parametrize("kwargs,match", [
    (dict(dims=(5, 4, 0), dtype="u1"), "dims"),
    (dict(dims=(5, 4), dtype="u1"), "dims"),
    (dict(dims=(5, 4, 3), dtype="u1", spacing=(1, 0, 1)), "spacing"),
    (dict(dims=(5, 4, 3), dtype="u1", spacing=(1, np.nan, 1)), "spacing"),
    (dict(dims=(5, 4, 3), dtype="u1", byte_order="middle"), "byte_order"),
    (dict(dims=(5, 4, 3), dtype="U4"), "dtype"),
])
def test_raw_bad_arguments(tmp_path, kwargs, match):
    (tmp_path / "v.raw").write_bytes(b"\x00" * 60)
    with pytest.raises(ValueError, match=match):
        read_raw(tmp_path / "v.raw", **kwargs)


def test_zero_spacing_is_rejected_by_every_reader(tmp_path):
    (tmp_path / "z.nrrd").write_bytes(b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nspacings: 1 0 1\n"
                                      b"encoding: raw\n\n" + bytes(8))
    (tmp_path / "z.mha").write_bytes(b"NDims = 3\nDimSize = 2 2 2\nElementSpacing = 1 1 0\nElementType = MET_UCHAR\n"
                                     b"ElementDataFile = LOCAL\n" + bytes(8))
    xml = '<DataArray type="UInt8" Name="density" format="ascii">' + " 0" * 8 + "</DataArray>"
    (tmp_path / "z.vti").write_bytes(_vti(xml, extent=(0, 1, 0, 1, 0, 1)).replace(b'Spacing="0.5 0.5 2"', b'Spacing="0 1 1"'))
    for name in ("z.nrrd", "z.mha", "z.vti"):
        with pytest.raises(ValueError, match="[Ss]pacing.*(0|positive)"):
            read_volume(tmp_path / name)
    with pytest.raises(ValueError, match="spacing"):
        Volume.from_array(np.zeros((2, 2, 2)), spacing=(1, 1, 0))


def test_missing_files_are_named(tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.nrrd"):
        read_volume(tmp_path / "nope.nrrd")
    (tmp_path / "v.nhdr").write_text("NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n"
                                     "data file: gone.raw\n")
    with pytest.raises(FileNotFoundError, match="gone.raw"):
        read_volume(tmp_path / "v.nhdr")
    (tmp_path / "v.mhd").write_text("NDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\nElementDataFile = gone2.raw\n")
    with pytest.raises(FileNotFoundError, match="gone2.raw"):
        read_volume(tmp_path / "v.mhd")


def test_truncated_and_unknown_files(tmp_path):
    (tmp_path / "t.mha").write_bytes(b"NDims = 3\nDimSize = 4 4 4\nElementType = MET_SHORT\n"
                                     b"ElementDataFile = LOCAL\n" + bytes(100))
    with pytest.raises(ValueError, match=r"100 bytes.*need 128"):
        read_volume(tmp_path / "t.mha")
    (tmp_path / "x.foo").write_text("?")
    with pytest.raises(ValueError, match="unrecognised volume file"):
        read_volume(tmp_path / "x.foo")
    (tmp_path / "x.raw").write_bytes(bytes(8))
    with pytest.raises(ValueError, match="read_raw"):
        read_volume(tmp_path / "x.raw")
    (tmp_path / "bad.nrrd").write_text("hello")
    with pytest.raises(ValueError, match="not a NRRD"):
        read_volume(tmp_path / "bad.nrrd")
    (tmp_path / "u.vtk").write_text("# vtk DataFile Version 3.0\nx\nASCII\nDATASET UNSTRUCTURED_GRID\n")
    with pytest.raises(ValueError, match="STRUCTURED_POINTS"):
        read_volume(tmp_path / "u.vtk")


def test_bad_volume_arrays():
    with pytest.raises(ValueError, match="NaN or Inf"):
        Volume.from_array(np.array([[[0.0, np.nan]]]))
    with pytest.raises(ValueError, match="3 axes"):
        Volume.from_array(np.zeros((2, 2)))
    with pytest.raises(ValueError, match="singular"):
        Volume.from_array(np.zeros((2, 2, 2)), direction=[[1, 0, 1], [0, 1, 1], [0, 0, 0]])
    with pytest.raises(TypeError, match="dtype"):
        Volume.from_array(np.zeros((2, 2, 2), dtype=complex))


def test_missing_optional_dependency_names_the_extra(tmp_path, monkeypatch):
    (tmp_path / "v.nii").write_bytes(bytes(352))
    (tmp_path / "v.nrrd").write_bytes(b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n\n"
                                      + bytes(8))
    (tmp_path / "d").mkdir()
    monkeypatch.setitem(sys.modules, "SimpleITK", None)  # makes `import SimpleITK` fail
    for name in ("v.nii", "v.nrrd", "d"):
        with pytest.raises(ImportError, match=r"needs SimpleITK.*pip install tetvr\[volumes\]"):
            read_volume(tmp_path / name)
    # VTK files and raw voxels need nothing beyond numpy.
    (tmp_path / "v.raw").write_bytes(bytes(8))
    assert read_raw(tmp_path / "v.raw", dims=(2, 2, 2), dtype="uint8").dims == (2, 2, 2)


def test_shared_folder_is_reported_when_absent(monkeypatch, tmp_path):
    # The data tests skip (with the path in the reason) rather than fail on a user's clone.
    from . import conftest

    monkeypatch.setattr(conftest, "SHARED", tmp_path / "absent")
    with pytest.raises(pytest.skip.Exception, match="shared data not available"):
        conftest.shared_file("volumes/LIDC2.mha")
    assert SHARED  # the real location is configured
