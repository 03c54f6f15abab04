"""The Python layers against the C ABI's table (rbss-abi; python/rbss/_abi.py is written from it
and checked fresh by ffi/tests/abi.rs): the ctypes layer declares every function of the table
from it, the library exports every one, and both implementations have one API and one ABI
version.
"""

import ctypes
import os

import pytest

import rbss
from rbss import _abi

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
MODEL = os.path.join(ROOT, "models", "stewart_6ups.toml")


@pytest.fixture(scope="module")
def ctypes_robot():
    return rbss.compile(MODEL, backend="ctypes")


def test_ctypes_declares_the_table(ctypes_robot):
    lib = ctypes_robot._lib
    assert len(_abi.FUNCTIONS) == 33
    for name, (ret, args) in _abi.FUNCTIONS.items():
        fn = getattr(lib, name)
        assert fn.restype is rbss._RETURN_TYPES[ret], name
        assert list(fn.argtypes or []) == [rbss._ARG_TYPES[k] for _, k, _ in args], name
    # A library without one of the table's functions is refused with its name.
    libc = ctypes.CDLL(None)
    with pytest.raises(rbss.RbssError, match="no function rbss_"):
        rbss._declare(libc, "libc")


def test_one_api_and_one_version():
    assert rbss.ABI_VERSION == _abi.ABI_VERSION == 4
    if not rbss.native_available():
        pytest.skip("rbss._native is not installed")
    assert rbss._native.ABI_VERSION == _abi.ABI_VERSION
    native = rbss.compile(MODEL, backend="native")
    ctypes_robot = rbss.compile(MODEL, backend="ctypes")
    public = lambda r: {a for a in dir(r) if not a.startswith("_")}  # noqa: E731
    assert public(native) == public(ctypes_robot)
