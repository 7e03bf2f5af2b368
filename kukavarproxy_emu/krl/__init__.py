"""KRL interpreter front end: lexer, AST and parser for the KRL subset KVP programs use.

``parse_src(text, filename)`` turns a ``.src``/``.sub`` module into an :class:`ast.Module`;
``parse_dat`` parses a module data list with the shared :mod:`pyopenshowvar.krl.datfile`
parser; ``read_src(path)`` reads a module and its ``.dat`` beside it. Every syntax error is a
:class:`KrlSyntaxError` whose message reads ``file:line:column: message`` plus the offending
line and a caret.
"""

from __future__ import annotations

from . import ast
from .lexer import KrlSyntaxError, Token, tokenize
from .parser import parse_dat, parse_src, read_src

__all__ = ["KrlSyntaxError", "Token", "ast", "parse_dat", "parse_src", "read_src", "tokenize"]
