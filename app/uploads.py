"""Streaming multipart upload: the file part goes to a temporary file under a byte limit.

The body is never held in memory: chunks are hashed and written as they arrive,
and the request is refused (413) as soon as the declared ``Content-Length`` or
the bytes actually received pass the limit. The file name's extension is
checked as soon as the part's headers arrive (415), before its bytes are read.
"""

from __future__ import annotations

import hashlib
import os
import uuid
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath, PureWindowsPath
from typing import TYPE_CHECKING, BinaryIO

from python_multipart.exceptions import MultipartParseError
from python_multipart.multipart import MultipartParser, parse_options_header
from starlette.requests import ClientDisconnect, Request

from worker.engine.formats import mesh_format

from .errors import InvalidInputError, PayloadTooLargeError, UnsupportedMediaTypeError
from .schemas import MAX_FILENAME
from .storage import ReceivedFile

if TYPE_CHECKING:  # defined for type checkers only
    from python_multipart.multipart import MultipartCallbacks

FILE_FIELD = "file"
MAX_FIELDS = 16


@dataclass
class MultipartUpload:
    file: ReceivedFile | None
    fields: dict[str, str] = field(default_factory=dict)

    def discard(self) -> None:
        if self.file is not None:
            self.file.path.unlink(missing_ok=True)


def safe_filename(raw: str) -> str:
    """The last path component of a client-supplied name, for display and format only.

    Raises
    ------
    InvalidInputError
        ``filename_too_long``: over ``MAX_FILENAME`` characters.
    """
    name = PureWindowsPath(PurePosixPath(raw).name).name.strip().replace("\x00", "")
    if len(name) > MAX_FILENAME:
        raise InvalidInputError(
            f"The file name is longer than {MAX_FILENAME} characters; send the file under a "
            "shorter name (its extension tells the format).",
            code="filename_too_long",
        )
    return name


def _mb(n: int) -> str:
    return f"{n / (1024 * 1024):.3g} MB"


class _Receiver:
    """Callbacks for ``MultipartParser``; state of the part being read."""

    def __init__(self, tmp_dir: Path, max_bytes: int, max_field_bytes: int) -> None:
        self.tmp_dir = tmp_dir
        self.max_bytes = max_bytes
        self.max_field_bytes = max_field_bytes
        self.fields: dict[str, str] = {}
        self.file: ReceivedFile | None = None
        self._header_field = b""
        self._header_value = b""
        self._headers: dict[bytes, bytes] = {}
        self._name: str | None = None
        self._is_file = False
        self._buffer = bytearray()
        self._fh: BinaryIO | None = None
        self._digest = hashlib.sha256()
        self._size = 0
        self._path: Path | None = None
        self._filename = ""

    # -- parser callbacks -------------------------------------------------
    def on_part_begin(self) -> None:
        self._headers = {}
        self._name = None
        self._is_file = False
        self._buffer = bytearray()

    def on_header_field(self, data: bytes, start: int, end: int) -> None:
        self._header_field += data[start:end]

    def on_header_value(self, data: bytes, start: int, end: int) -> None:
        self._header_value += data[start:end]

    def on_header_end(self) -> None:
        self._headers[self._header_field.strip().lower()] = self._header_value.strip()
        self._header_field = b""
        self._header_value = b""

    def on_headers_finished(self) -> None:
        _, params = parse_options_header(self._headers.get(b"content-disposition", b""))
        name = params.get(b"name", b"").decode("utf-8", "replace")
        self._name = name
        filename = params.get(b"filename")
        if name == FILE_FIELD:
            if self.file is not None or self._path is not None:
                raise InvalidInputError(
                    "Send exactly one file in the 'file' field.", code="too_many_files"
                )
            shown = safe_filename(filename.decode("utf-8", "replace")) if filename else ""
            if not shown:
                raise InvalidInputError(
                    "The 'file' part has no file name; the name's extension tells the format.",
                    code="missing_filename",
                )
            mesh_format(shown)  # UnsupportedFormatError -> 415 before any byte is stored
            self._is_file = True
            self._filename = shown
            self.tmp_dir.mkdir(parents=True, exist_ok=True)
            self._path = self.tmp_dir / f"upload-{uuid.uuid4().hex}"
            self._fh = open(self._path, "wb")  # noqa: SIM115 - closed in on_part_end/cleanup
        elif len(self.fields) >= MAX_FIELDS:
            raise InvalidInputError("The form has too many fields.", code="too_many_fields")

    def on_part_data(self, data: bytes, start: int, end: int) -> None:
        chunk = data[start:end]
        if self._is_file:
            self._size += len(chunk)
            if self._size > self.max_bytes:
                raise PayloadTooLargeError(
                    f"The file is larger than this service's limit of {_mb(self.max_bytes)}."
                )
            self._digest.update(chunk)
            assert self._fh is not None
            self._fh.write(chunk)
        else:
            self._buffer += chunk
            if len(self._buffer) > self.max_field_bytes:
                raise PayloadTooLargeError(
                    f"The form field '{self._name}' is longer than {self.max_field_bytes:,} bytes.",
                    code="field_too_large",
                )

    def on_part_end(self) -> None:
        if self._is_file:
            assert self._fh is not None and self._path is not None
            self._fh.flush()
            os.fsync(self._fh.fileno())  # the original upload must survive a crash
            self._fh.close()
            self._fh = None
            self.file = ReceivedFile(
                self._path, self._filename, self._size, self._digest.hexdigest()
            )
        elif not self._name:
            raise InvalidInputError(
                "A part of the form has no name: name every field "
                "(Content-Disposition: form-data; name=...).",
                code="unnamed_field",
            )
        else:
            if self._name in self.fields:  # keeping one of the values silently would be a guess
                raise InvalidInputError(
                    f"The form field '{self._name}' was sent more than once; send each field once.",
                    code="repeated_field",
                )
            self.fields[self._name] = self._buffer.decode("utf-8", "replace")

    # ---------------------------------------------------------------------
    def callbacks(self) -> MultipartCallbacks:
        return {
            "on_part_begin": self.on_part_begin,
            "on_header_field": self.on_header_field,
            "on_header_value": self.on_header_value,
            "on_header_end": self.on_header_end,
            "on_headers_finished": self.on_headers_finished,
            "on_part_data": self.on_part_data,
            "on_part_end": self.on_part_end,
        }

    def cleanup(self) -> None:
        if self._fh is not None:
            self._fh.close()
        if self._path is not None:
            self._path.unlink(missing_ok=True)


async def receive_multipart(
    request: Request, *, tmp_dir: Path, max_bytes: int, max_field_bytes: int
) -> MultipartUpload:
    """Read a ``multipart/form-data`` request with at most one mesh file.

    Raises
    ------
    UnsupportedMediaTypeError
        Not multipart, or the file's extension is not a mesh format (415).
    PayloadTooLargeError
        Declared or received size over the limits (413).
    InvalidInputError
        A malformed body (422).
    """
    content_type, params = parse_options_header(request.headers.get("content-type", ""))
    boundary = params.get(b"boundary")
    if content_type != b"multipart/form-data" or not boundary:
        raise UnsupportedMediaTypeError(
            "Send the mesh as multipart/form-data with the file in a field called 'file'.",
            code="expected_multipart",
        )
    body_limit = max_bytes + MAX_FIELDS * (max_field_bytes + 1024)
    declared = request.headers.get("content-length")
    if declared is not None:
        try:
            declared_bytes = int(declared)
        except ValueError:
            raise InvalidInputError(
                "The Content-Length header is not a number.", code="bad_content_length"
            ) from None
        if declared_bytes > body_limit:
            raise PayloadTooLargeError(
                f"The request declares {declared_bytes:,} bytes; this service accepts files "
                f"up to {_mb(max_bytes)}."
            )

    receiver = _Receiver(tmp_dir, max_bytes, max_field_bytes)
    parser = MultipartParser(boundary, receiver.callbacks())
    received = 0
    try:
        async for chunk in request.stream():
            received += len(chunk)
            if received > body_limit:
                raise PayloadTooLargeError(
                    f"The request is larger than this service's limit of {_mb(max_bytes)}."
                )
            parser.write(chunk)
        parser.finalize()
    except MultipartParseError as exc:
        receiver.cleanup()
        if "header size" in str(exc):  # a part's header line over the parser's 4 kB
            raise InvalidInputError(
                "A form part's header is longer than 4 kB: a file name may have at most "
                f"{MAX_FILENAME} characters.",
                code="filename_too_long",
            ) from None
        raise InvalidInputError(
            "The multipart body is malformed.", code="malformed_multipart"
        ) from exc
    except ClientDisconnect:
        receiver.cleanup()
        raise InvalidInputError("The upload was interrupted.", code="upload_interrupted") from None
    except BaseException:
        receiver.cleanup()
        raise
    if receiver._fh is not None:  # the body ended inside the file part
        receiver.cleanup()
        raise InvalidInputError("The multipart body is truncated.", code="malformed_multipart")
    return MultipartUpload(receiver.file, receiver.fields)
