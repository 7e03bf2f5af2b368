"""prompt_toolkit completer for KRL variable names and the REPL's ``:`` commands.

KRL names contain ``$``, ``@``, ``[``, ``]`` and ``.``, which prompt_toolkit's default word
completer treats as separators, so the word under the cursor is cut here by hand. Matching is
case-insensitive (KRL is) and also works without the leading ``$``. A name that would read as
unknown carries its reason as the completion's meta text (shown beside it in the menu) and
comes after the names that read.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from typing import Any

from prompt_toolkit.completion import CompleteEvent, Completer, Completion
from prompt_toolkit.document import Document

COMMANDS = (":watch", ":raw", ":stats", ":ping", ":help", ":quit")


class NameCompleter(Completer):
    """Completes the first word with variable names (and ``:`` commands); ``:watch`` args too."""

    def __init__(self, names: Iterable[str]) -> None:
        self.names = sorted(set(names))
        self._note: Any = getattr(names, "note", None)  # a names.Names: live notes

    def get_completions(
        self, document: Document, complete_event: CompleteEvent
    ) -> Iterator[Completion]:
        before = document.text_before_cursor
        words = before.split()
        word = "" if not words or before[-1:].isspace() else words[-1]
        first = len(words) == 0 or (len(words) == 1 and word)
        if first and word.startswith(":"):
            for cmd in COMMANDS:
                if cmd.startswith(word):
                    yield Completion(cmd, start_position=-len(word))
            return
        if not first and not before.lstrip().startswith(":watch"):
            return
        key = word.upper()
        bare = key.lstrip("$")
        marked: list[Completion] = []
        for name in self.names:
            upper = name.upper()
            if upper.startswith(key) or (
                bare and not key.startswith("$") and upper.lstrip("$").startswith(bare)
            ):
                note = self._note(name) if self._note is not None else ""
                if note:
                    marked.append(
                        Completion(
                            name, start_position=-len(word), display_meta=note, style="fg:ansigray"
                        )
                    )
                else:
                    yield Completion(name, start_position=-len(word))
        yield from marked
