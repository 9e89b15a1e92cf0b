"""Userdata: the blackboard states share, with each state limited to the keys it declares.

SMACH's lesson: a state that silently reads a key nobody wrote is a bug that shows up late.
So a state sees its declared ``input_keys`` (read) and ``output_keys`` (write) only, and an
undeclared access raises at once with the state's name.
"""
from __future__ import annotations

from collections.abc import Iterable, Iterator, MutableMapping
from typing import Any


class UserData(MutableMapping[str, Any]):
    """A plain blackboard; :meth:`view` gives a state its restricted window onto it."""

    def __init__(self, **initial: Any) -> None:
        self._data: dict[str, Any] = dict(initial)

    def __getitem__(self, key: str) -> Any:
        return self._data[key]

    def __setitem__(self, key: str, value: Any) -> None:
        self._data[key] = value

    def __delitem__(self, key: str) -> None:
        del self._data[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._data)

    def __len__(self) -> int:
        return len(self._data)

    def __repr__(self) -> str:
        return f"UserData({self._data!r})"

    def view(self, owner: str, input_keys: Iterable[str], output_keys: Iterable[str]) -> UserDataView:
        return UserDataView(self, owner, frozenset(input_keys), frozenset(output_keys))


class UserDataView(MutableMapping[str, Any]):
    """A state's window: reads limited to input keys (and outputs), writes to output keys."""

    def __init__(self, data: UserData, owner: str, inputs: frozenset[str], outputs: frozenset[str]) -> None:
        self._data = data
        self._owner = owner
        self._readable = inputs | outputs
        self._writable = outputs

    def __getitem__(self, key: str) -> Any:
        if key not in self._readable:
            raise KeyError(f"state {self._owner!r} reads userdata key {key!r} it did not declare as an input")
        return self._data[key]

    def __setitem__(self, key: str, value: Any) -> None:
        if key not in self._writable:
            raise KeyError(f"state {self._owner!r} writes userdata key {key!r} it did not declare as an output")
        self._data[key] = value

    def __delitem__(self, key: str) -> None:
        if key not in self._writable:
            raise KeyError(f"state {self._owner!r} deletes userdata key {key!r} it did not declare as an output")
        del self._data[key]

    def __iter__(self) -> Iterator[str]:
        return (k for k in self._data if k in self._readable)

    def __len__(self) -> int:
        return sum(1 for _ in self)
