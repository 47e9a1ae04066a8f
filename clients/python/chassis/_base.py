"""What the generated contract (``_contract.py``) is made of: the base of every IPC type
(``Struct``), of every group of constants (``Constants``), and the text field (``TextField``), a
NUL-padded UTF-8 byte array of the layout that reads and assigns as a ``str``.

Written by hand; ``generate.py`` writes ``_contract.py`` on top of it.
"""

from __future__ import annotations

import ctypes
from collections.abc import Callable
from typing import Any, TypeVar, overload

_S = TypeVar("_S", bound="type[Struct]")


class Struct(ctypes.Structure):
    """Base of every IPC type: a ``#[repr(C)]`` Rust struct with a versioned type name."""

    _type_name = ""

    @classmethod
    def type_name(cls) -> str:
        """The iceoryx2 type name, the same as the Rust type's."""
        return cls._type_name

    def to_dict(self) -> dict[str, Any]:
        """Every field by name, nested structs and arrays as dicts and lists."""
        return {name: _plain(getattr(self, name)) for name, _ in self._fields_}

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.to_dict()!r})"


def _plain(value: Any) -> Any:
    if isinstance(value, Struct):
        return value.to_dict()
    if isinstance(value, ctypes.Array):
        return [_plain(v) for v in value]
    return value


class Constants:
    """A group of named constants (an enum or a set of flags) from the contract."""

    NAMES: dict[int, str] = {}
    FLAGS = False

    @classmethod
    def name(cls, value: int) -> str:
        """The name of ``value`` ("unknown" when it has none); flags joined by ``|``."""
        if cls.FLAGS:
            return "|".join(cls.names(value)) or "none"
        return cls.NAMES.get(value, "unknown")

    @classmethod
    def names(cls, value: int) -> list[str]:
        """The names of the flags set in ``value``."""
        return [n for v, n in sorted(cls.NAMES.items()) if v and value & v == v]


class TextField:
    """A text field of the contract: NUL-padded UTF-8 bytes in the sample, a ``str`` in Python.

    Reading gives the bytes up to the first NUL as UTF-8, cut at the first invalid byte (as
    ``read_fixed_str`` reads them in Rust). Assigning a ``str`` writes it NUL-padded; text longer
    than the field is refused. ``offset`` and ``size`` are those of the byte array.
    """

    def __init__(self, field: Any) -> None:
        self._field = field

    @property
    def offset(self) -> int:
        """Bytes from the start of the struct."""
        return int(self._field.offset)

    @property
    def size(self) -> int:
        """Length of the byte array."""
        return int(self._field.size)

    @overload
    def __get__(self, obj: None, owner: type | None = None) -> TextField: ...

    @overload
    def __get__(self, obj: Struct, owner: type | None = None) -> str: ...

    def __get__(self, obj: Struct | None, owner: type | None = None) -> TextField | str:
        if obj is None:
            return self
        raw = bytes(self._field.__get__(obj, type(obj))).split(b"\0", 1)[0]
        try:
            return raw.decode()
        except UnicodeDecodeError as e:
            return raw[: e.start].decode()

    def __set__(self, obj: Struct, text: str) -> None:
        if not isinstance(text, str):
            raise TypeError(f"a text field takes a str, not {type(text).__name__}")
        raw = text.encode()
        if len(raw) > self.size:
            raise ValueError(f"'{text}' is longer than {self.size} bytes")
        self._field.__get__(obj, type(obj))[:] = raw.ljust(self.size, b"\0")


def _text_fields(*names: str) -> Callable[[_S], _S]:
    """Makes the byte arrays ``names`` of the decorated class text fields (:class:`TextField`)."""

    def wrap(cls: _S) -> _S:
        for name in names:
            setattr(cls, name, TextField(cls.__dict__[name]))
        return cls

    return wrap
