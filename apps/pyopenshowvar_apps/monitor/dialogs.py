"""Modal dialogs of the monitor: one-line input and a yes/no confirmation.

Both return their answer through ``dismiss`` (``push_screen(dialog, callback)``); Escape
cancels (None / False). The confirmation defaults to *No*: Enter on it does not write.
"""

from __future__ import annotations

from typing import ClassVar

from textual import events
from textual.app import ComposeResult
from textual.binding import Binding, BindingType
from textual.containers import Horizontal, Vertical
from textual.screen import ModalScreen
from textual.widgets import Button, Input, Label

_CSS = """
InputDialog, ConfirmDialog { align: center middle; }
#dialog { width: 72; height: auto; border: thick $accent; background: $surface; padding: 0 1; }
#dialog Horizontal { height: auto; align: right middle; }
#dialog Button { margin: 0 1; min-width: 8; }
"""


class InputDialog(ModalScreen[str | None]):
    """Ask for one line of text (a variable name, a KRL value)."""

    DEFAULT_CSS = _CSS
    BINDINGS: ClassVar[list[BindingType]] = [Binding("escape", "cancel", "Cancel")]

    def __init__(self, prompt: str, value: str = "", placeholder: str = "") -> None:
        super().__init__()
        self.prompt = prompt
        self.value = value
        self.placeholder = placeholder
        #: Keys were typed ahead into the value (see :meth:`type_ahead`).
        self._typed = False
        #: Enter (True) or Escape (False) typed ahead before the dialog was mounted.
        self._answered: bool | None = None

    def compose(self) -> ComposeResult:
        with Vertical(id="dialog"):
            yield Label(self.prompt)
            yield Input(
                self.value,
                placeholder=self.placeholder,
                id="answer",
                # a value typed ahead must not be selected when the focus arrives: the next
                # key would replace it
                select_on_focus=not self._typed,
            )
            yield Label("Enter: OK   Esc: cancel", classes="hint")

    def on_mount(self) -> None:
        if self._typed:  # keys typed ahead while the input was being composed: into it
            self._type_into(self.query_one("#answer", Input), self.value)
        if self._answered is not None:
            self._finish(self._answered)

    @staticmethod
    def _type_into(answer: Input, text: str) -> None:
        answer.select_on_focus = False
        answer.value = text
        answer.cursor_position = len(text)

    def type_ahead(self, event: events.Key) -> bool:
        """Type a key that was pressed before the input had the focus into it; False when it
        is not a key of a one-line input (left for the bindings).

        A fast typist presses ``e``, the value and Enter at once: the monitor handles ``e``
        only once the keys after it have gone to the watch table, and the dialog's input
        exists only once it is mounted. Those keys were lost (and a ``1`` among them switched
        the tab) until they were typed here, as the focused input would: the first character
        replaces the value shown (the input selects it when it gets the focus), Backspace
        deletes, Enter answers, Escape cancels.
        """
        # the input exists once the dialog is mounted, and until it is taken down
        found = self.query("#answer") if self.is_mounted else None
        answer = found.first(Input) if found else None
        text = answer.value if answer is not None else self.value
        if event.key in ("enter", "escape"):
            if answer is None:
                self._answered = event.key == "enter"  # answered once it is mounted
            else:
                self._finish(event.key == "enter")
            return True
        if event.key == "backspace":
            text = text[:-1]
        elif event.is_printable and event.character:
            text = (text if self._typed else "") + event.character
        else:
            return False
        self._typed = True
        if answer is None:
            self.value = text
        else:
            self._type_into(answer, text)
        return True

    def on_key(self, event: events.Key) -> None:
        # keys that reach the screen itself arrived while nothing had the focus
        if self.focused is None and self.type_ahead(event):
            event.stop()
            event.prevent_default()

    def _finish(self, ok: bool) -> None:
        if not ok:
            self.dismiss(None)
            return
        answer = self.query("#answer").first(Input)
        self.dismiss(answer.value.strip() or None)

    def on_input_submitted(self, event: Input.Submitted) -> None:
        self.dismiss(event.value.strip() or None)

    def action_cancel(self) -> None:
        self.dismiss(None)


class ConfirmDialog(ModalScreen[bool]):
    """Yes/No before writing a motion variable. ``y`` confirms, ``n``/Esc cancels."""

    DEFAULT_CSS = _CSS
    BINDINGS: ClassVar[list[BindingType]] = [
        Binding("y", "answer(True)", "Yes"),
        Binding("n", "answer(False)", "No"),
        Binding("escape", "answer(False)", "Cancel"),
    ]

    def __init__(self, question: str) -> None:
        super().__init__()
        self.question = question

    def compose(self) -> ComposeResult:
        with Vertical(id="dialog"):
            yield Label(self.question)
            with Horizontal():
                yield Button("Yes, write (y)", variant="warning", id="yes")
                yield Button("No (n)", variant="primary", id="no")

    def on_mount(self) -> None:
        self.query_one("#no", Button).focus()

    def on_button_pressed(self, event: Button.Pressed) -> None:
        self.dismiss(event.button.id == "yes")

    def action_answer(self, yes: bool) -> None:
        self.dismiss(yes)
