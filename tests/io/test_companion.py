"""Companion files of scenes (simfab.io.companion): every failure to read one is an InputError
naming the file, never a library's own exception."""

import numpy as np
import pytest

from simfab.errors import InputError
from simfab.io.companion import read_csv_numbers, read_npz


@pytest.fixture
def npz(tmp_path):
    p = tmp_path / "part.npz"
    np.savez(p, points=np.zeros((4, 3)), elements=np.array([[0, 1, 2, 3]]))
    return p


@pytest.mark.parametrize("damage, match", [
    (lambda b: b[:40], "cannot read the .*: BadZipFile"),  # truncated
    (lambda b: b[: len(b) // 2], "cannot read the .*: BadZipFile"),
    (lambda b: b"", "cannot read the .*: EOFError"),
    (lambda b: b"points,elements\n", "cannot read the "),  # a text file named .npz
])
def test_a_damaged_npz_names_the_file(npz, damage, match):
    npz.write_bytes(damage(npz.read_bytes()))
    with pytest.raises(InputError, match=match) as e:
        read_npz(npz, ("points", "elements"))
    assert str(e.value).startswith(str(npz))


def test_npz_arrays_missing_pickled_or_single(tmp_path, npz):
    got = read_npz(npz, ("points", "elements"))
    assert got["points"].shape == (4, 3) and got["elements"].tolist() == [[0, 1, 2, 3]]
    with pytest.raises(InputError, match="no array 'faces'"):
        read_npz(npz, ("points", "faces"))
    np.savez(tmp_path / "obj.npz", points=np.array([{"a": 1}], dtype=object))
    with pytest.raises(InputError, match="obj.npz: cannot read"):  # never unpickled
        read_npz(tmp_path / "obj.npz", ("points",))
    np.save(tmp_path / "one.npy", np.zeros(3))
    (tmp_path / "one.npy").rename(tmp_path / "one.npz")
    with pytest.raises(InputError, match="one.npz: a single array"):
        read_npz(tmp_path / "one.npz", ("points",))
    with pytest.raises(InputError, match="not found"):
        read_npz(tmp_path / "absent.npz", ("points",))


@pytest.mark.parametrize("text", ["0,0\n1,0\n1,1\n", "x,y\n0,0\n1,0\n1,1\n", "\ufeffx_m, y_m\n0,0\n1,0\n1,1\n",
                                  "# outline\n\nx,y\n0, 0\n1,0\n\n1,1\n"])
def test_csv_numbers_with_or_without_a_header_row(tmp_path, text):
    p = tmp_path / "o.csv"
    p.write_text(text, encoding="utf-8")
    np.testing.assert_array_equal(read_csv_numbers(p, 2), [[0, 0], [1, 0], [1, 1]])


@pytest.mark.parametrize("content, match", [
    ("0,0\nx,y\n", "line 2: expected 2 comma-separated numbers"),  # a header only comes first
    ("0,0\n1,0,0\n", "line 2: expected 2"),
    ("0,0\n1,nan\n", "line 2: .* is not finite"),
    ("x,y\n", "at least 1 row"),
    (b"\xff\xfe\x00\x01\x02", "cannot read the CSV file: UnicodeDecodeError"),
])
def test_bad_csv_names_the_file_and_line(tmp_path, content, match):
    p = tmp_path / "bad.csv"
    (p.write_bytes if isinstance(content, bytes) else p.write_text)(content)
    with pytest.raises(InputError, match=match) as e:
        read_csv_numbers(p, 2)
    assert str(e.value).startswith(str(p))
