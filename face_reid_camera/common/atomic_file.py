"""Files written whole or not at all: through a temporary file of the writer's own in the target's folder, renamed
over the target. Two writers of one file (two simulators sharing a cache) never collide; the last to finish wins.
"""

from __future__ import annotations

import io
import os
import tempfile
import zipfile
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import IO, Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["write_atomically", "write_npz"]


def write_atomically(path: str | Path, write: Callable[[IO[bytes]], None], mode: int = 0o644) -> None:
    """Create ``path`` (and its folder) from what ``write`` writes to a binary file, atomically, with ``mode``
    (mkstemp's 0600 would keep shared files from their readers); on any error nothing is left behind."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    tmp = Path(name)
    try:
        with os.fdopen(fd, "wb") as handle:
            write(handle)
        tmp.chmod(mode)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_npz(path: str | Path, arrays: Mapping[str, NDArray[Any]], compress: bool = False) -> None:
    """An .npz of ``arrays`` (no pickles) with fixed zip timestamps, byte-identical for identical arrays, written
    atomically; ``compress``: deflated (else stored, the fastest to load)."""
    method = zipfile.ZIP_DEFLATED if compress else zipfile.ZIP_STORED

    def write(handle: IO[bytes]) -> None:
        with zipfile.ZipFile(handle, "w", compression=method, allowZip64=True) as zf:
            for name in sorted(arrays):
                buf = io.BytesIO()
                np.lib.format.write_array(buf, np.ascontiguousarray(arrays[name]), allow_pickle=False)
                info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
                info.external_attr = 0o644 << 16
                info.compress_type = method
                zf.writestr(info, buf.getvalue())

    write_atomically(path, write)
