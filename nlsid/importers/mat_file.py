"""MATLAB ``.mat`` files: v4/v5/v7 through scipy.io, v7.3 (HDF5 underneath) through h5py.

A signal is named by its variable, or by a dotted path into a struct (``data.u``), and one record
of a matrix by its index (``Acceleration[1]``, ``data.acc[2]``; :mod:`nlsid.importers.variables`).
v7.3 files store arrays column-major, so h5py sees them transposed; they are transposed back to
MATLAB's shape. Only numeric arrays are read (MATLAB classes double, single and the integer classes).
The other variables are surveyed: sample-rate variables (``fs``, ``Ts``, ...), scalars, and the
ignored ones (``details["ignored_variables"]``).
"""

from __future__ import annotations

import struct
from pathlib import Path

import h5py
import numpy as np

from nlsid.errors import InputError
from nlsid.io.hdf5_recording import H5PY_ERRORS, hdf5_damage, link_name
from nlsid.importers.source import NotFound, Source, option, pick, source_from
from nlsid.importers.variables import Leaf, check_pairing, matrix_channels, record_of, split_index, survey

NUMERIC_CLASSES = {"double", "single", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64", "logical"}


def is_mat73(path: Path) -> bool:
    """A v7.3 MAT-file is an HDF5 file (with a 512-byte MATLAB header as user block)."""
    return h5py.is_hdf5(path)


def read_mat(path: Path, names: dict[str, str], time: str | None, optional: set[str]) -> Source:
    """Read the selected variables (signal -> variable or struct.field) of a MAT-file."""
    wanted = dict(names, **({"time": time} if time else {}))
    if is_mat73(path):
        return _read_v73(path, wanted, optional)
    return _read_v5(path, wanted, optional)


def _struct_of(name: str) -> str:
    """The struct holding ``name`` (``data`` for ``data.u``; "" at the top)."""
    return name.rpartition(".")[0]


def _source(path: Path, version: str, wanted: dict[str, str], values: dict[str, np.ndarray], leaves: list[Leaf]) -> Source:
    """The Source of the values read (a channel's matrix as one channel per record), with the
    file's other variables surveyed."""
    wanted, values, split, notes = matrix_channels(wanted, values, lambda key, name: f"{path}: {option(key, name)}")
    check_pairing(path, wanted, values)
    used = {key: wanted[key] for key in values}
    source = source_from(path, f"mat v{version}", wanted, values, {"variables": used})
    source.split_channels, source.notes = split, notes
    survey(source, "variable", leaves, used, _struct_of)
    return source


V4_ITEMSIZE = {0: 8, 1: 4, 2: 4, 3: 2, 4: 2, 5: 1}  # precision P of MOPT: double, single, int32, int16, uint16, uint8


def mat_file_problem(path: Path) -> str | None:
    """Why ``path`` is not a MATLAB v4 or v5/v7 file whose variables fit in it (None: it is).

    A v5/v7 file starts with a 116-byte text header and ends its 128-byte header with the endian
    indicator ``IM`` (little-endian) or ``MI``; its variables follow as data elements (tag: u32
    type, u32 byte count). A v4 file has no header: each variable is five int32 (type flag ``MOPT``:
    machine M 0..4, O 0, precision P 0..5, text/sparse T 0..2; rows; columns; imaginary flag; name
    length), the name and the data. Sizes are checked against the file before scipy reads it, so
    a damaged size field gives this message instead of an attempt to allocate it.
    """
    size = path.stat().st_size
    with open(path, "rb") as handle:
        head = handle.read(128)
        if len(head) >= 128 and head[126:128] in (b"IM", b"MI"):
            return _v5_problem(handle, size, "<" if head[126:128] == b"IM" else ">")
        if len(head) >= 20 and _v4_flag(int.from_bytes(head[:4], "little", signed=True)) or \
                len(head) >= 20 and _v4_flag(int.from_bytes(head[:4], "big", signed=True)):
            little = 0 <= int.from_bytes(head[:4], "little", signed=True) <= 5000  # as scipy guesses it
            return _v4_problem(handle, size, "<" if little else ">")
    if head.startswith(b"MATLAB"):
        return f"truncated MAT-file header ({len(head)} of 128 bytes)" if len(head) < 128 else \
            "damaged MAT-file header (no endian indicator IM or MI at bytes 126-127)"
    return "not a MATLAB file (no MAT-file header: MATLAB v5/v7 files start with a 128-byte 'MATLAB ...' " \
           "header, v7.3 files are HDF5)"


def _v4_flag(mopt: int) -> bool:
    return 0 <= mopt < 5000 and mopt // 100 % 10 == 0 and mopt // 10 % 10 in V4_ITEMSIZE and mopt % 10 <= 2


def _v5_problem(handle, size: int, order: str) -> str | None:
    position = 128
    while position + 8 <= size:
        handle.seek(position)
        _, count = struct.unpack(f"{order}II", handle.read(8))
        if position + 8 + count > size:
            return (f"truncated or damaged MAT-file: the variable at byte {position} claims {count} bytes, "
                    f"the file holds {size - position - 8} after its tag")
        position += 8 + count
    return None


def _v4_problem(handle, size: int, order: str) -> str | None:
    position = 0
    while position < size:
        handle.seek(position)
        header = handle.read(20)
        if len(header) < 20:
            return f"truncated MAT-file (v4): the variable header at byte {position} is cut"
        mopt, rows, columns, imaginary, name_length = struct.unpack(f"{order}5i", header)
        if not _v4_flag(mopt) or rows < 0 or columns < 0 or imaginary not in (0, 1) or name_length < 1:
            return (f"damaged MAT-file (v4): the variable header at byte {position} reads type {mopt}, {rows} x "
                    f"{columns}, imaginary flag {imaginary}, name length {name_length}")
        data = rows * columns * V4_ITEMSIZE[mopt // 10 % 10] * (1 + imaginary)
        end = position + 20 + name_length + data
        if end > size:
            return (f"truncated or damaged MAT-file (v4): the variable at byte {position} ({rows} x {columns}) "
                    f"needs {data} bytes of data, the file holds {max(size - position - 20 - name_length, 0)}")
        position = end
    return None


def _library_errors() -> tuple[type[BaseException], ...]:
    """What scipy.io raises on damaged MAT-file content: its MatReadError, ValueError, TypeError and
    OSError; zlib.error for a compressed variable that does not inflate; ArithmeticError for a count
    read from the file that does not fit (a field name length of 0 divides by zero), and IndexError
    and KeyError, the same fault in an index or a code; UnboundLocalError for an array of a class
    code MATLAB does not have (scipy's reader falls through its class cases). zlib.error,
    ZeroDivisionError and UnboundLocalError were found by tests/cli/test_fuzz_inputs.py.
    NotImplementedError: HDF5-based (v7.3) content scipy cannot read. Only the call of loadmat
    is wrapped, so these never hide nlsid's own errors."""
    import zlib

    from scipy.io.matlab import MatReadError

    return (MatReadError, ValueError, TypeError, OSError, zlib.error, ArithmeticError, IndexError, KeyError,
            UnboundLocalError, NotImplementedError)


def _read_v5(path: Path, wanted: dict[str, str], optional: set[str]) -> dict[str, np.ndarray]:
    problem = mat_file_problem(path)
    if problem is not None:
        raise InputError(str(path), problem)
    content = _loadmat_isolated(path)
    variables = {k: v for k, v in content.items() if not k.startswith("__")}

    def read(key: str, name: str) -> np.ndarray:
        base, index = split_index(name)
        where = f"{path}: {option(key, name)}"
        value = _lookup(variables, base, where)
        return value if index is None else record_of(value, index, base, where)

    return _source(path, "5", wanted, pick(wanted, optional, read), list(_leaves_v5(variables)))


def _leaves_v5(variables: dict, scope: str = ""):
    """The variables and struct fields of a loaded v4/v5/v7 file (scipy's simplified cells)."""
    for name, obj in variables.items():
        full = f"{scope}.{name}" if scope else name
        if isinstance(obj, dict):
            if obj:
                yield from _leaves_v5(obj, full)
            else:
                yield Leaf(full, scope, "empty struct")
            continue
        if isinstance(obj, str):
            yield Leaf(full, scope, "text")
        elif hasattr(obj, "toarray"):  # scipy.sparse: MATLAB's sparse matrices
            yield Leaf(full, scope, f"sparse {'x'.join(map(str, obj.shape))}")
        elif isinstance(obj, list):
            yield Leaf(full, scope, f"cell or struct array of {len(obj)}")
        else:
            arr = np.asarray(obj)
            if arr.dtype.kind in "biuf":
                yield Leaf(full, scope, "real", arr.shape, lambda arr=arr: arr)
            elif arr.dtype.kind == "c":
                yield Leaf(full, scope, "complex", arr.shape)
            else:
                yield Leaf(full, scope, f"{'cell' if arr.dtype.kind == 'O' else arr.dtype.name} array "
                                        f"{'x'.join(map(str, arr.shape))}")


def _loadmat(path: Path) -> dict:
    """``scipy.io.loadmat``, its errors on damaged content as InputError."""
    from scipy.io import loadmat

    try:
        return loadmat(path, simplify_cells=True)
    except _library_errors() as exc:
        reason = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        if isinstance(exc, UnboundLocalError):
            reason = "an array of a class MATLAB does not have"
        elif isinstance(exc, (ArithmeticError, IndexError, KeyError)):
            reason = f"a damaged count or index: {type(exc).__name__}: {reason}"
        raise InputError(str(path), f"cannot read as a MATLAB file ({reason})") from None
    except MemoryError:  # a size field inside a compressed variable, which mat_file_problem cannot see
        raise InputError(str(path), "cannot read as a MATLAB file (it asks for more memory than there is: a "
                                    "damaged size field, or a file too large for this machine)") from None


def _loadmat_isolated(path: Path) -> dict:
    """:func:`_loadmat` in a forked child process, where the platform can fork.

    scipy's compiled MAT v5 reader trusts the type codes and lengths in the file, and a damaged
    file can crash the interpreter: tests/cli/test_fuzz_inputs.py found segmentation faults (a data
    element of a reserved type, 0, 8, 10, 11 or 19, or a matrix type, where an array's numbers
    are). A crashed child takes only itself down, and its signal becomes one error line. Forking
    costs a few milliseconds: the child starts with scipy already imported.
    """
    import multiprocessing

    import scipy.io  # noqa: F401  (imported here, so that the child starts with it)

    if "fork" not in multiprocessing.get_all_start_methods():
        return _loadmat(path)
    context = multiprocessing.get_context("fork")
    receive, send = context.Pipe(duplex=False)
    child = context.Process(target=_loadmat_child, args=(path, send), daemon=True)
    child.start()
    send.close()
    try:
        outcome = receive.recv()
    except EOFError:  # the child died before it could answer
        outcome = None
    finally:
        receive.close()
        child.join()
    if outcome is None:
        how = f"signal {-child.exitcode}" if child.exitcode is not None and child.exitcode < 0 else f"exit code {child.exitcode}"
        raise InputError(str(path), f"cannot read as a MATLAB file (scipy's MAT-file reader crashed on it, {how}: "
                                    "a damaged file?)")
    kind, value = outcome
    if kind == "damaged":
        raise InputError(str(path), value)
    if kind == "failed":  # not the file's fault: a programming error, shown with its traceback
        raise RuntimeError(f"reading {path} with scipy.io.loadmat failed in the child process:\n{value}")
    return value


def _loadmat_child(path: Path, send) -> None:
    import faulthandler
    import traceback

    faulthandler.disable()  # a crash on a damaged file is expected here and reported by the parent
    try:
        send.send(("ok", _loadmat(path)))
    except InputError as exc:
        send.send(("damaged", exc.what))
    except Exception:
        send.send(("failed", traceback.format_exc()))
    finally:
        send.close()


def _lookup(variables: dict, name: str, where: str) -> np.ndarray:
    obj = variables
    parts = name.split(".")
    for depth, part in enumerate(parts):
        if not isinstance(obj, dict) or part not in obj:
            inside = ".".join(parts[:depth])
            scope = f"fields of {inside}" if depth else "variables"
            found = ", ".join(sorted(obj)) if isinstance(obj, dict) else f"none ({inside} is not a struct)"
            raise NotFound(where, f"no variable {name!r}; {scope}: {found or '(none)'}")
        obj = obj[part]
    if isinstance(obj, dict):
        raise InputError(where, f"{name} is a struct with fields {', '.join(sorted(obj))}; name one of them ({name}.FIELD)")
    arr = np.asarray(obj)
    if arr.dtype.kind not in "biufc":
        raise InputError(where, f"{name} is not a numeric array (MATLAB {type(obj).__name__} of {arr.dtype})")
    return arr


def _read_v73(path: Path, wanted: dict[str, str], optional: set[str]) -> dict[str, np.ndarray]:
    try:
        handle = h5py.File(path, "r")
    except H5PY_ERRORS as exc:
        raise InputError(str(path), f"cannot open MATLAB v7.3 file ({' '.join(str(exc).split())})") from None
    def read(key: str, name: str) -> np.ndarray:
        base, index = split_index(name)
        where = f"{path}: {option(key, name)}"
        value = _v73_variable(handle, base, where)
        return value if index is None else record_of(value, index, base, where)

    with handle:
        values = pick(wanted, optional, read)
        with hdf5_damage(str(path)):  # the survey reads scalars and rate variables
            return _source(path, "7.3", wanted, values, list(_leaves_v73(handle)))


def _leaves_v73(group: h5py.Group, scope: str = ""):
    """The variables and struct fields of a v7.3 file (HDF5 groups are structs; names starting
    with ``#`` are MATLAB's own: references of cells, class data)."""
    for key in group:
        name = link_name(key)
        if name.startswith("#"):
            continue
        full = f"{scope}.{name}" if scope else name
        obj = group.get(key)
        if isinstance(obj, h5py.Group):
            members = [m for m in map(link_name, obj) if not m.startswith("#")]
            if members:
                yield from _leaves_v73(obj, full)
            else:
                yield Leaf(full, scope, "empty struct")
            continue
        if not isinstance(obj, h5py.Dataset):
            yield Leaf(full, scope, "link")
            continue
        cls = obj.attrs.get("MATLAB_class", b"double")
        cls = cls.decode() if isinstance(cls, bytes) else str(cls)
        dims = tuple(obj.shape[::-1])
        if obj.attrs.get("MATLAB_empty", 0):
            yield Leaf(full, scope, f"empty {cls}")
        elif cls not in NUMERIC_CLASSES:
            yield Leaf(full, scope, f"MATLAB {cls} {'x'.join(map(str, dims))}")
        elif obj.dtype.names:
            yield Leaf(full, scope, "complex", dims)
        else:
            yield Leaf(full, scope, "real", dims, lambda obj=obj: np.asarray(obj[()]).T)


def _v73_variable(handle: h5py.File, name: str, where: str) -> np.ndarray:
    with hdf5_damage(where):
        return _v73_array(handle, name, where)


def _v73_array(handle: h5py.File, name: str, where: str) -> np.ndarray:
    group: h5py.Group = handle
    parts = name.split(".")
    for depth, part in enumerate(parts):
        if part not in group or part.startswith("#"):
            inside = ".".join(parts[:depth])
            scope = f"fields of {inside}" if depth else "variables"
            found = ", ".join(sorted(k for k in map(link_name, group) if not k.startswith("#")))
            raise NotFound(where, f"no variable {name!r}; {scope}: {found or '(none)'}")
        obj = group[part]
        if isinstance(obj, h5py.Group):
            group = obj
            continue
        if depth != len(parts) - 1:
            raise InputError(where, f"{'.'.join(parts[:depth + 1])} is not a struct")
        cls = obj.attrs.get("MATLAB_class", b"double")
        cls = cls.decode() if isinstance(cls, bytes) else str(cls)
        if cls not in NUMERIC_CLASSES or obj.dtype.names:
            raise InputError(where, f"{name} is a MATLAB {cls}{' (complex)' if obj.dtype.names else ''} array; "
                                    "expected real numbers")
        return np.asarray(obj[()]).T
    raise InputError(where, f"{name} is a struct with fields {', '.join(sorted(map(link_name, group)))}; "
                            f"name one of them ({name}.FIELD)")
