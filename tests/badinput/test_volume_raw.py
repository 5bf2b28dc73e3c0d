"""Bad raw volumes (``tetvr.io.volume_file.read_raw``): a file whose size does not match
dims x dtype, nonsense geometry or types - each a ValueError (FileNotFoundError for a
missing file) naming the value; the voxels are never reinterpreted silently."""

from __future__ import annotations

import numpy as np
import pytest

from tetvr.io.volume_file import read_raw


@pytest.fixture
def raw(tmp_path):
    path = tmp_path / "v.raw"
    np.arange(24, dtype=np.uint8).tofile(path)  # 2 x 3 x 4 voxels of one byte
    return path


RAW_BAD = [
    ("dims-too-many-voxels", dict(dims=(2, 3, 5), dtype="uint8"), r"has 24 bytes, but dims \(2, 3, 5\) x uint8 .* need 30"),
    ("dims-too-few-voxels", dict(dims=(2, 3, 3), dtype="uint8"), r"has 24 bytes, .* need 18"),
    ("dtype-too-wide", dict(dims=(2, 3, 4), dtype="uint16"), r"has 24 bytes, but dims \(2, 3, 4\) x uint16 \(2 bytes\) need 48"),
    ("header-eats-voxels", dict(dims=(2, 3, 4), dtype="uint8", header_bytes=4), r"\+ 4 header bytes need 28"),
    ("header-negative", dict(dims=(2, 3, 4), dtype="uint8", header_bytes=-1), "header_bytes must be >= 0, got -1"),
    ("spacing-zero", dict(dims=(2, 3, 4), dtype="uint8", spacing=(0, 1, 1)), r"spacing must be positive along every axis, got \[0\.0, 1\.0, 1\.0\]"),
    ("spacing-negative", dict(dims=(2, 3, 4), dtype="uint8", spacing=(1, -1, 1)), "spacing must be positive along every axis"),
    ("spacing-nan", dict(dims=(2, 3, 4), dtype="uint8", spacing=(np.nan, 1, 1)), "spacing must be 3 finite numbers"),
    ("spacing-two-values", dict(dims=(2, 3, 4), dtype="uint8", spacing=(1, 1)), "spacing must be 3 finite numbers"),
    ("origin-inf", dict(dims=(2, 3, 4), dtype="uint8", origin=(0, np.inf, 0)), "origin must be 3 finite numbers"),
    ("direction-singular", dict(dims=(2, 3, 4), dtype="uint8", direction=[[1, 0, 0], [0, 1, 0], [0, 0, 0]]), "direction"),
    ("dims-zero", dict(dims=(2, 3, 0), dtype="uint8"), r"dims must be 3 positive integers .* got \(2, 3, 0\)"),
    ("dims-two", dict(dims=(4, 6), dtype="uint8"), r"dims must be 3 positive integers .* got \(4, 6\)"),
    ("dims-fraction", dict(dims=(2, 3, 4.5), dtype="uint8"), "dims must be 3 positive integers"),
    ("dtype-complex", dict(dims=(2, 3, 4), dtype="complex64"), "dtype must be an integer or float type, got complex64"),
    ("dtype-unknown", dict(dims=(2, 3, 4), dtype="nonsense"), "dtype 'nonsense' is not a numpy dtype"),
    ("byte-order-unknown", dict(dims=(2, 3, 4), dtype="uint8", byte_order="middle"), "byte_order must be 'little' or 'big'"),
]


@pytest.mark.parametrize("kwargs,match", [c[1:] for c in RAW_BAD], ids=[c[0] for c in RAW_BAD])
def test_bad_raw_volume(raw, kwargs, match):
    with pytest.raises(ValueError, match=match):
        read_raw(raw, **kwargs)


def test_raw_volume_file_missing(tmp_path):
    with pytest.raises(FileNotFoundError, match="nothere.raw"):
        read_raw(tmp_path / "nothere.raw", dims=(1, 1, 1), dtype="uint8")


def test_good_raw_volume_reads(raw):
    vol = read_raw(raw, dims=(2, 3, 4), dtype="uint8", spacing=(0.5, 1, 2))
    assert vol.dims == (2, 3, 4) and vol.data[3, 2, 1] == 3 * 6 + 2 * 2 + 1


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_float_raw_volume_with_nan_or_inf(tmp_path, bad):
    data = np.arange(8, dtype=np.float32)
    data[5] = bad
    path = tmp_path / "f.raw"
    data.tofile(path)
    with pytest.raises(ValueError, match="data contain 1 NaN or Inf"):
        read_raw(path, dims=(2, 2, 2), dtype="float32")
