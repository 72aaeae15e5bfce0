"""One registry type for every named choice: scenarios, world models, measures,
exploration orderings and experiment presets.

A registry is the single list the CLI's choices, the docs and the tests'
parametrization read. It maps names to entries, knows its default (when the kind has
one), accepts aliases, and fails an unknown name with one error that lists the known
ones. Entries may be filled on first use (``loader``), so importing a registry costs
nothing until a name is looked up.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator, Mapping
from typing import Generic, TypeVar

from llcps.errors import UnknownNameError

T = TypeVar("T")


class Registry(Mapping[str, T], Generic[T]):
    """Named entries of one kind, in registration order.

    Args:
        kind: what an entry is, for errors ("world model", "measure", ...).
        entries: name -> entry, in the order to list them.
        default: the name used when a command is given none (must be registered).
        aliases: other names that resolve to a registered name.
        loader: called once, on first use, to fill ``entries`` (name -> entry) and
            ``aliases`` lazily; for registries read from files.
        hint_extra: shown after the known names in an unknown-name error.
    """

    def __init__(
        self,
        kind: str,
        entries: Mapping[str, T] | None = None,
        *,
        default: str | None = None,
        aliases: Mapping[str, str] | None = None,
        loader: Callable[[], tuple[Mapping[str, T], Mapping[str, str]]] | None = None,
        hint_extra: tuple[str, ...] = (),
    ) -> None:
        self.kind = kind
        self._entries: dict[str, T] = dict(entries or {})
        self._aliases: dict[str, str] = dict(aliases or {})
        self._loader = loader
        self._lock = threading.Lock()
        self._default = default
        self._hint_extra = hint_extra
        if loader is None:
            self._check_default()

    def _check_default(self) -> None:
        if self._default is not None and self._default not in self._entries:
            raise ValueError(f"default {self.kind} {self._default!r} is not registered")

    def _loaded(self) -> dict[str, T]:
        if self._loader is not None:
            with self._lock:
                if self._loader is not None:
                    entries, aliases = self._loader()
                    self._entries.update(entries)
                    self._aliases.update(aliases)
                    self._loader = None
                    self._check_default()
        return self._entries

    # Mapping
    def __getitem__(self, name: str) -> T:
        return self._loaded()[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._loaded())

    def __len__(self) -> int:
        return len(self._loaded())

    def __contains__(self, name: object) -> bool:
        return name in self._loaded()

    def __repr__(self) -> str:
        return f"Registry({self.kind!r}, {list(self._loaded())!r})"

    @property
    def default(self) -> str:
        """The name a command uses when given none."""
        if self._default is None:
            raise LookupError(f"the {self.kind} registry has no default")
        return self._default

    @property
    def aliases(self) -> Mapping[str, str]:
        """alias -> registered name."""
        self._loaded()
        return dict(self._aliases)

    def canonical(self, name: str) -> str:
        """The registered name of ``name`` (itself or the name it is an alias of).

        Raises:
            UnknownNameError: listing the known names.
        """
        entries = self._loaded()
        if name in entries:
            return name
        if name in self._aliases:
            return self._aliases[name]
        raise UnknownNameError(self.kind, name, [*self.names_with_aliases(), *self._hint_extra])

    def get_entry(self, name: str) -> T:
        """The entry of ``name`` or of the name it is an alias of.

        Raises:
            UnknownNameError: listing the known names.
        """
        return self._loaded()[self.canonical(name)]

    def names_with_aliases(self) -> list[str]:
        """Every name, followed by its aliases in brackets: ``scenario2 (container)``."""
        by_name: dict[str, list[str]] = {}
        for alias, name in self._aliases.items():
            by_name.setdefault(name, []).append(alias)
        return [f"{name} ({', '.join(by_name[name])})" if name in by_name else name for name in self._loaded()]

    def register(self, name: str, entry: T) -> T:
        """Add an entry (a name already registered is an error)."""
        entries = self._loaded()
        if name in entries or name in self._aliases:
            raise ValueError(f"{self.kind} {name!r} is registered already")
        entries[name] = entry
        return entry
