"""A measurement file read once: its bytes, its text, its lines, and progress on big files.

Every reader and format sniffer works on a :class:`Source`, so a file is read
from disk (or from a pipe such as ``<(cat file)`` or ``/dev/stdin``) exactly
once: sniffing the format looks at the bytes already in memory instead of
reopening, and consuming, the stream.

Text must be UTF-8 (a byte-order mark is allowed) or UTF-16 with its byte-order
mark (the "Unicode text" export of spreadsheets). A file in another encoding
(Latin-1, Windows-1252, ...) is refused with the line and byte of the first
character that is not UTF-8 and the way to convert it for its format: the
single-byte encodings cannot be told apart from the bytes (0xB5 is "µ" in
both Latin-1 and Windows-1252, 0x80 is "€" in one and a control code in the
other), and a wrong guess would silently change sample names, so bayespig does
not guess.
"""

from __future__ import annotations

import errno
import os
import sys
from pathlib import Path

from tqdm import tqdm

from .errors import MeasurementError, Problem

__all__ = ["LARGE_FILE_BYTES", "Source", "load"]

#: Files larger than this show a progress bar on stderr while read (``progress=None``) [bytes].
LARGE_FILE_BYTES = 20 * 2**20
#: How much of the file the format sniffers look at [bytes].
SNIFF_BYTES = 64 * 2**10
#: Progress is reported about this many times over a file.
PROGRESS_STEPS = 100

_UTF16_BOMS = (b"\xff\xfe", b"\xfe\xff")
#: Advice for a file that is not UTF-8, per format.
_ENCODING_ADVICE = {
    "csv": "save it as UTF-8 (in a spreadsheet: 'CSV UTF-8'), or convert it, e.g. "
    "'iconv -f WINDOWS-1252 -t UTF-8 FILE > NEW.csv'",
    "astm_e1392": "ASTM E1392 files are read as UTF-8 text; convert it, e.g. "
    "'iconv -f WINDOWS-1252 -t UTF-8 FILE > NEW.astm'",
    "spectral_table": "export the table as UTF-8 text, or convert it, e.g. "
    "'iconv -f WINDOWS-1252 -t UTF-8 FILE > NEW.txt'",
}


def _open_problem(path, error):
    """Plain words for an OSError raised opening or reading ``path``."""
    if error.errno == errno.ELOOP:
        return "symbolic link loop: the link points (through other links) back to itself"
    if isinstance(error, FileNotFoundError):
        if os.path.islink(path):
            return f"symbolic link to a missing file ({os.readlink(path)})"
        return "file not found"
    if isinstance(error, IsADirectoryError):
        return "is a folder, not a file"
    if isinstance(error, PermissionError):
        return "permission denied: cannot read the file"
    return f"cannot read the file: {error.strerror or error}"


def _utf16(data, errors="strict"):
    """The text of UTF-16 data with a byte-order mark ("Unicode text" of spreadsheets), or None.

    Measurement files are mostly digits and separators: data that decodes to less than 90 %
    ASCII is binary that happens to start like a byte-order mark, not UTF-16 text.
    """
    if data[:2] not in _UTF16_BOMS:
        return None
    try:
        text = data.decode("utf-16", errors=errors)
    except UnicodeDecodeError:
        return None
    ascii_share = sum(c.isascii() for c in text[:SNIFF_BYTES]) / max(1, len(text[:SNIFF_BYTES]))
    return text if ascii_share >= 0.9 else None


class Source:
    """One file's content, read once.

    Parameters
    ----------
    name : str
        The file name used in messages.
    data : bytes
        The file's content.

    Attributes
    ----------
    name : str
    size : int
        Length of the file [bytes].
    """

    def __init__(self, name, data):
        self.name = name
        self.size = len(data)
        self._data = data
        self._lines = None

    def head(self):
        """The first :data:`SNIFF_BYTES` as text (undecodable bytes replaced), for sniffing."""
        if self._data is None:
            return "\n".join(self._lines[:200])
        text = _utf16(self._data[:SNIFF_BYTES], errors="replace")  # may end mid-character
        if text is None:
            text = self._data[:SNIFF_BYTES].decode("utf-8", errors="replace")
        return text.removeprefix("\ufeff")

    def lines(self, file_format):
        """The lines (universal newlines), or a MeasurementError naming the first non-UTF-8 byte.

        Parameters
        ----------
        file_format : {"csv", "astm_e1392", "spectral_table"}
            Selects the advice given for a file that is not UTF-8.
        """
        if self._lines is None:
            data = self._data
            text = _utf16(data)
            try:
                if text is None:
                    text = data.decode("utf-8-sig")
            except UnicodeDecodeError as error:
                line_start = data.rfind(b"\n", 0, error.start) + 1
                row = data.count(b"\n", 0, error.start) + 1
                byte = data[error.start]
                raise MeasurementError(
                    Problem(
                        f"byte {error.start - line_start + 1} of the line (0x{byte:02X}, "
                        f"{bytes([byte]).decode('cp1252', errors='replace')!r} in Windows-1252) "
                        f"is not UTF-8 text; {_ENCODING_ADVICE[file_format]}",
                        file=self.name,
                        row=row,
                    )
                ) from None
            self._data = data = None  # keep one copy of the content, not two
            if "\r" in text:
                text = text.replace("\r\n", "\n").replace("\r", "\n")
            self._lines = text.split("\n")
        return self._lines

    def take_lines(self, file_format):
        """:meth:`lines`, handed over: the Source keeps no reference, so a reader can free
        each line once parsed (``lines[i] = None``) and hold a big file once, not twice."""
        lines = self.lines(file_format)
        self._lines = []
        return lines

    def progress(self, progress, total):
        """A function ``update(done)`` reporting how many of ``total`` lines are read.

        Parameters
        ----------
        progress : None, bool or callable
            None: a progress bar on stderr when the file is larger than
            :data:`LARGE_FILE_BYTES`; False: nothing; True: always a bar;
            a callable: called as ``progress(done, total)`` about
            :data:`PROGRESS_STEPS` times (``done`` lines of ``total``).
        total : int
            Number of lines.

        Returns
        -------
        update : callable
            ``update(done)`` (cheap to call on every line), and ``update.close()``.
        """
        if progress is None:
            progress = self.size > LARGE_FILE_BYTES
        step = max(1, total // PROGRESS_STEPS)
        state = {"next": step}
        if progress is False:
            report = None
        elif progress is True:
            bar = tqdm(
                total=total,
                unit=" lines",
                desc=f"reading {self.name}",
                file=sys.stderr,
                unit_scale=True,
                leave=False,
            )

            def report(done, total):
                bar.update(done - bar.n)
        elif callable(progress):
            report = progress
        else:
            raise TypeError(f"progress must be None, True, False or a callable, got {progress!r}")

        def update(done):
            if report is not None and done >= state["next"]:
                state["next"] = done + step
                report(done, total)

        def close():
            if report is not None:
                report(total, total)
                if progress is True:
                    bar.close()

        update.close = close
        return update


#: First bytes of netCDF-4 (HDF5) and classic netCDF files: a posterior, not measurements.
NETCDF_SIGNATURES = (b"\x89HDF\r\n\x1a\n", b"CDF\x01", b"CDF\x02", b"CDF\x05")


def load(path):
    """A :class:`Source` for ``path`` (read once; a Source is returned as it is).

    Raises
    ------
    MeasurementError
        When the file cannot be read, in plain words (not found, symbolic link
        loop, a folder, permission denied).
    """
    if isinstance(path, Source):
        return path
    name = str(path)
    try:
        data = Path(path).read_bytes()
    except OSError as error:
        raise MeasurementError(Problem(_open_problem(name, error), file=name)) from None
    if data.startswith(NETCDF_SIGNATURES):
        raise MeasurementError(Problem(
            "this is a netCDF file (a bayespig posterior?), not a measurement file; a posterior goes "
            "to 'bayespig report', measurements are a bayespig CSV, an ASTM E1392 file or a wide "
            "spectral table", file=name))
    return Source(name, data)
