"""The bridge to SimpleITK, and the NIfTI and DICOM readers, which are ITK's alone.

About this stage
----------------
ITK (through SimpleITK) reads NRRD, MetaImage, NIfTI and DICOM for :mod:`tetvr.io.volume_file`:
its image becomes a :class:`~tetvr.volume.volume.Volume` with ITK's geometry (``origin + D
diag(spacing) ijk``, the same index -> world map), its errors become ValueErrors without
ITK's source paths. NIfTI's header and DICOM's slices are read first (sizes checked
against the file and this machine's memory, the rescale checked finite, slice positions
checked distinct) and only then the voxels. SimpleITK is the optional extra
``pip install tetvr[volumes]``; nothing here imports it until a file is read.
"""

from __future__ import annotations

import math
import os
import re
from pathlib import Path
from typing import Any

import numpy as np

from tetvr.core.checks import check_input_file, warn
from tetvr.io.voxels import _DEFLATE_MAX_RATIO, _check_declared, _check_file, _is_dir, _to_space
from tetvr.volume.volume import Volume

__all__ = ["read_nifti", "read_dicom"]

_EXTRA_HINT = "install the optional volume readers with  pip install tetvr[volumes]  (or pip install SimpleITK)"


# ---------------------------------------------------------------------------------
# SimpleITK: the reader, its errors, its images as Volumes
# ---------------------------------------------------------------------------------


def _sitk(what: str) -> Any:
    try:
        import SimpleITK
    except ImportError as exc:
        raise ImportError(f"reading {what} needs SimpleITK, which is not installed; " + _EXTRA_HINT) from exc
    return SimpleITK


def _itk_message(exc: BaseException) -> str:
    """ITK's message without its source paths, line numbers and object addresses."""
    lines = []
    for line in str(exc).splitlines():
        line = re.sub(r"^.*?\.(cxx|h|hxx|txx):\d+:\s*", "", line.strip())
        line = re.sub(r"^(itk|ITK|sitk)::?\s*ERROR:\s*(\w+\(0x[0-9a-f]+\):\s*)?", "", line)
        line = re.sub(r"^Exception thrown in SimpleITK \w+:\s*", "", line)
        if line:
            lines.append(line)
    return "; ".join(lines) or type(exc).__name__


def _itk_dtype(sitk: Any, pixel_id: int) -> np.dtype[Any]:
    names = {"sitkUInt8": "u1", "sitkInt8": "i1", "sitkUInt16": "u2", "sitkInt16": "i2", "sitkUInt32": "u4",
             "sitkInt32": "i4", "sitkUInt64": "u8", "sitkInt64": "i8", "sitkFloat32": "f4", "sitkFloat64": "f8"}
    for name, code in names.items():
        if getattr(sitk, name) == pixel_id:
            return np.dtype(code)
    raise ValueError(f"ITK pixel type {sitk.GetPixelIDValueAsString(pixel_id)!r} is not a scalar type")


def _itk_header(sitk: Any, path: Path | str, what: str, *, io: str = "") -> Any:
    """An ImageFileReader that has read ``path``'s header (and nothing more)."""
    reader = sitk.ImageFileReader()
    if io:
        reader.SetImageIO(io)
    reader.SetFileName(str(path))
    try:
        reader.ReadImageInformation()
    except RuntimeError as exc:
        raise ValueError(f"cannot read {what}: {_itk_message(exc)}") from None
    return reader


def _itk_execute(reader: Any, what: str) -> Any:
    try:
        return reader.Execute()
    except RuntimeError as exc:
        raise ValueError(f"cannot read the voxels of {what}: {_itk_message(exc)}") from None


def _volume_from_itk(sitk: Any, img: Any, what: str, *, scalar_name: str, space: str) -> Volume:
    """An ITK image as a Volume: ITK's index -> world map (``origin + D diag(spacing) ijk``,
    D's columns the index axes) is the Volume's; 2D images become one slice; axes of
    length 1 beyond the third are dropped."""
    if img.GetNumberOfComponentsPerPixel() != 1:
        raise ValueError(f"{what} has {img.GetNumberOfComponentsPerPixel()} components per voxel: "
                         "only scalar volumes are read")
    dim = img.GetDimension()
    data = sitk.GetArrayFromImage(img)  # index order reversed: (z, y, x)
    size = list(img.GetSize())
    if dim > 3 and all(s == 1 for s in size[3:]):
        data, dim = data.reshape(data.shape[dim - 3:]), 3
    elif dim > 3:
        raise ValueError(f"{what} has {dim} dimensions {size}: only one 3D scalar volume is read")
    n = img.GetDimension()
    spacing = np.ones(3)
    origin = np.zeros(3)
    direction = np.eye(3)
    k = min(n, 3)
    spacing[:k] = img.GetSpacing()[:k]
    origin[:k] = img.GetOrigin()[:k]
    direction[:k, :k] = np.asarray(img.GetDirection(), dtype=np.float64).reshape(n, n)[:k, :k]
    if data.ndim == 2:
        data = data[None]
    return Volume(data=data, spacing=spacing, origin=origin, direction=direction, scalar_name=scalar_name, space=space)


# ---------------------------------------------------------------------------------
# NIfTI and DICOM
# ---------------------------------------------------------------------------------


def read_nifti(path: str | os.PathLike[str], *, space: str = "LPS") -> Volume:
    """Read a NIfTI-1/2 volume (``.nii``, ``.nii.gz``) with ITK.

    ITK's NiftiImageIO chooses the sform or qform, applies ``scl_slope``/``scl_inter``
    (the data then become float) and gives the geometry in LPS; 4D files with one volume
    are squeezed. The declared dimensions are checked against the file's size and this
    machine's memory before any voxel is read.

    Examples
    --------
    >>> vol = read_nifti("../shared/data/volumes/avg152T1_RL_nifti.nii.gz", space="RAS")  # doctest: +SKIP
    >>> vol.origin.tolist()                                                               # doctest: +SKIP
    [-90.0, -126.0, -72.0]
    """
    p = _check_file(Path(path), "NIfTI file")
    sitk = _sitk("NIfTI files")
    gz = p.name.lower().endswith(".gz")
    with open(p, "rb") as f:
        magic = f.read(2)
    if gz and magic != b"\x1f\x8b":
        raise ValueError(f"cannot read NIfTI file {p.name!r}: its name ends in .gz, but it is not a gzip file")
    what = f"NIfTI file {p.name!r}"
    reader = _itk_header(sitk, p, what, io="NiftiImageIO")
    dims = tuple(int(v) for v in reader.GetSize())
    dtype = _itk_dtype(sitk, reader.GetPixelID()) if reader.GetNumberOfComponents() == 1 else np.dtype("f4")
    size = p.stat().st_size
    _check_declared(dims, dtype, what, how=" (gzip)" if gz else "",
                    holds=size * _DEFLATE_MAX_RATIO if gz else max(size - 348, 0))
    img = _itk_execute(reader, what)
    vol = _volume_from_itk(sitk, img, what, scalar_name=p.name.split(".")[0], space="LPS")
    return _to_space(vol, space)


def read_dicom(path: str | os.PathLike[str], *, space: str = "LPS") -> Volume:
    """Read a DICOM series (a directory of slices) or a single slice with ITK (GDCM).

    GDCM groups the files by SeriesInstanceUID (the largest series is read; a warning
    names the others) and orders the slices along their normal by ImagePositionPatient;
    ITK applies RescaleSlope/Intercept (CT values become Hounsfield units). Slices at the
    position of another are refused, uneven spacing is warned about, and the rescale
    must be finite. Integer results are kept in 16 bits when they fit.

    Examples
    --------
    >>> vol = read_dicom("ct_series/")  # doctest: +SKIP
    """
    p = Path(path)
    is_dir = _is_dir(p)
    if not is_dir:
        check_input_file(p, "DICOM file or directory")
    sitk = _sitk("DICOM series")
    where = str(p)
    if is_dir:
        shown = sitk.ProcessObject.GetGlobalWarningDisplay()
        sitk.ProcessObject.SetGlobalWarningDisplay(False)  # GDCM's "No Series were found": said below, once
        try:
            ids = sitk.ImageSeriesReader.GetGDCMSeriesIDs(where)
        finally:
            sitk.ProcessObject.SetGlobalWarningDisplay(shown)
        if not ids:
            raise ValueError(f"{where!r} is a folder with no DICOM images in it (a folder is read as a DICOM "
                             "series, one file a slice); name a folder of DICOM slices, or a volume or mesh file")
        series = {uid: list(sitk.ImageSeriesReader.GetGDCMSeriesFileNames(where, uid)) for uid in ids}
        uid = max(series, key=lambda k: len(series[k]))
        if len(series) > 1:
            others = {k: len(v) for k, v in series.items() if k != uid}
            warn(f"{where!r} holds {len(series)} DICOM series; reading {uid!r} ({len(series[uid])} slices), "
                 f"ignoring {others}")
        names = series[uid]
    else:
        names = [where]
    headers = [_itk_header(sitk, n, f"DICOM file {n!r}", io="GDCMImageIO") for n in names]
    for n, h in zip(names, headers):
        _dicom_rescale(h, n)
        _dicom_check_pixel_bytes(h, n)
    first = headers[0]
    dims = tuple(int(v) for v in first.GetSize()[:2]) + (len(names),)
    _check_declared(dims, _itk_dtype(sitk, first.GetPixelID()) if first.GetNumberOfComponents() == 1
                    else np.dtype("u1"), f"DICOM series in {where!r}")
    if len(names) > 1:
        _dicom_check_positions(headers, where)
    if len(names) == 1:
        reader = first
    else:
        reader = sitk.ImageSeriesReader()
        reader.SetFileNames(names)
        reader.SetImageIO("GDCMImageIO")
    img = _itk_execute(reader, f"DICOM series in {where!r}")
    modality = first.GetMetaData("0008|0060").strip() if first.HasMetaDataKey("0008|0060") else "dicom"
    vol = _volume_from_itk(sitk, img, f"DICOM series in {where!r}", scalar_name=modality or "dicom", space="LPS")
    data = vol.data
    if data.dtype.kind in "iu" and data.dtype.itemsize > 2 and data.size:
        lo, hi = int(data.min()), int(data.max())
        for cand in (np.dtype("i2"), np.dtype("i4")):
            if cand.itemsize < data.dtype.itemsize and np.iinfo(cand).min <= lo and hi <= np.iinfo(cand).max:
                vol = Volume(data=data.astype(cand), spacing=vol.spacing, origin=vol.origin, direction=vol.direction,
                             scalar_name=vol.scalar_name, space=vol.space)
                break
    return _to_space(vol, space)


#: Transfer syntaxes whose pixel data are stored as they are (implicit/explicit VR, little or
#: big endian), and the deflated one (deflate holds at most 1032 times its size).
_DICOM_PLAIN = {"1.2.840.10008.1.2", "1.2.840.10008.1.2.1", "1.2.840.10008.1.2.2"}
_DICOM_DEFLATED = "1.2.840.10008.1.2.1.99"


def _dicom_transfer_syntax(path: str) -> str:
    """The file's Transfer Syntax UID (0002,0010) from its meta header, or "" if it has none
    (a bare data set is implicit VR little endian: stored as it is)."""
    with open(path, "rb") as f:
        head = f.read(4096)
    at = head.find(b"\x02\x00\x10\x00UI")
    if at < 0 or at + 8 > len(head):
        return ""
    n = int.from_bytes(head[at + 6:at + 8], "little")
    return head[at + 8:at + 8 + n].decode("ascii", "replace").strip("\x00 ")


def _dicom_check_pixel_bytes(reader: Any, where: str) -> None:
    """A slice that declares more pixel bytes than its file can hold is refused before ITK
    reads it: GDCM returns such an image (rows x columns of whatever memory held) instead
    of an error, and copying it out allocates what the header claims."""
    size = reader.GetSize()
    bits = _dicom_numbers(reader, "0028|0100") or [16.0]
    samples = _dicom_numbers(reader, "0028|0002") or [1.0]
    dims = (int(size[0]), int(size[1]), int(size[2]) if len(size) > 2 else 1)
    dtype = np.dtype(f"u{max(1, int(bits[0]) // 8)}") if int(bits[0]) in (8, 16, 32, 64) else np.dtype("u2")
    syntax = _dicom_transfer_syntax(where)
    nbytes = os.stat(where).st_size
    what = f"DICOM file {os.path.basename(where)!r}"
    if int(samples[0]) != 1:
        dims = (dims[0] * int(samples[0]), dims[1], dims[2])
    if syntax in _DICOM_PLAIN or syntax == "":
        _check_declared(dims, dtype, what, holds=nbytes)
    elif syntax == _DICOM_DEFLATED:
        _check_declared(dims, dtype, what, how=" (deflated)", holds=_DEFLATE_MAX_RATIO * nbytes)


def _dicom_numbers(reader: Any, tag: str) -> list[float] | None:
    if not reader.HasMetaDataKey(tag):
        return None
    try:
        return [float(v) for v in reader.GetMetaData(tag).replace("\\", " ").split()]
    except ValueError:
        return None


def _dicom_rescale(reader: Any, where: str) -> tuple[float, float]:
    """A slice's (RescaleSlope, RescaleIntercept): finite, the slope non-zero; absent -> (1, 0)."""
    out = []
    for key, tag, default in (("RescaleSlope", "0028|1053", 1.0), ("RescaleIntercept", "0028|1052", 0.0)):
        text = reader.GetMetaData(tag).strip() if reader.HasMetaDataKey(tag) else ""
        try:
            number = default if text == "" else float(text)
        except ValueError:
            number = math.nan
        slope = key == "RescaleSlope"
        if not math.isfinite(number) or (slope and number == 0):
            raise ValueError(f"DICOM {where!r}: {key} must be a finite{' non-zero' if slope else ''} number, "
                             f"got {text!r}")
        out.append(number)
    return out[0], out[1]


def _dicom_check_positions(headers: list[Any], where: str) -> None:
    """Slices at one position are refused (duplicates, or several acquisitions in one
    series); uneven gaps are warned about (ITK spaces the slices by the first gap)."""
    iop = _dicom_numbers(headers[0], "0020|0037")
    ipp = [_dicom_numbers(h, "0020|0032") for h in headers]
    if iop is None or len(iop) != 6 or any(v is None or len(v) != 3 for v in ipp):
        return
    normal = np.cross(iop[:3], iop[3:])
    along = np.sort(np.asarray(ipp, dtype=np.float64) @ normal)
    gaps = np.diff(along)
    dz = float(np.median(gaps))
    same = int(np.sum(gaps <= 1e-6 * max(abs(dz), 1.0)))
    if same:
        raise ValueError(f"DICOM series in {where!r} has {same} slice(s) at the position of another "
                         "(duplicates or several acquisitions)")
    if np.max(np.abs(gaps - dz)) > 1e-3 * max(dz, 1.0) + 1e-4:
        warn(f"the slices of the DICOM series in {where!r} are not evenly spaced "
             f"({gaps.min():.4g} to {gaps.max():.4g} apart); they are placed {gaps[0]:.4g} apart")
