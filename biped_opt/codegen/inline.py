"""Exact inlining on the syntax tree, and pruning of unread assignments.

The DOP853 step calls the vector field and the stage probe twelve times each; Numba's own
inlining of them costs compile time, so the generator writes the copies itself.
:func:`expand` replaces each call of a generated function by the function's body, read as a
syntax tree and written back with its parameters and locals as slots (only names or numbers
fill a slot; any other argument is first bound to a name, as a call evaluates it): never by
pasting an argument's text into a body. :func:`prune` drops the assignments a function never
reads, which Numba would otherwise type in every inlined copy.
"""

from __future__ import annotations

import ast
import io
import math
import re
import tokenize
from collections import Counter
from dataclasses import dataclass
from typing import cast

__all__ = ["prune", "literal_node", "expand"]


_ASSIGNMENT = re.compile(r"\s+(\w+) = [^=]+")


def prune(lines: list[str]) -> list[str]:
    """``lines`` without the assignments to names that their function never reads (bindings
    of symbols it does not use, ``x = y[yo + 0]``, and values no output needs): Numba types
    every statement of every inlined copy, so unread ones cost compile time (the stage probes,
    inlined eleven times, read three of the biped's 26 symbols). Every such assignment is a
    pure expression of the generated code, so dropping it changes nothing else."""
    starts = [k for k, line in enumerate(lines) if line.startswith("def ")] + [len(lines)]
    out = lines[: starts[0]]
    for a, b in zip(starts, starts[1:]):
        body = lines[a:b]
        while True:
            # (a name on no line but its own assignment's: counted once over the body)
            seen = Counter(w for line in body for w in set(re.findall(r"\w+", line)))
            unread = {k for k, line in enumerate(body) if (m := _ASSIGNMENT.fullmatch(line))
                      and seen[m[1]] == 1}
            if not unread:
                break
            body = [line for k, line in enumerate(body) if k not in unread]
        out += body
    return out


_WORD = re.compile(r"[A-Za-z_]\w*")


def literal_node(value: float) -> ast.expr:
    """``value`` as a syntax node; a negative one as a negation, which ``ast.unparse``
    brackets where needed ((-2.0) ** 2, where a negative constant would print as -2.0 ** 2)."""
    if value < 0 or (value == 0 and math.copysign(1.0, value) < 0):
        return ast.UnaryOp(ast.USub(), ast.Constant(-value))
    return ast.Constant(value)


def _end_line(node: ast.expr | ast.stmt) -> int:
    """The last line of ``node`` (1-based), which ``ast.parse`` always records."""
    return cast(int, node.end_lineno)


def _segment(lines: list[str], node: ast.expr) -> str:
    """The source text of ``node`` (``lines``: its module's, ASCII)."""
    first, last = node.lineno - 1, _end_line(node) - 1
    if first == last:
        return lines[first][node.col_offset:node.end_col_offset]
    return "\n".join([lines[first][node.col_offset:], *lines[first + 1:last],
                      lines[last][:node.end_col_offset]])


def _statement_text(lines: list[str], stmt: ast.stmt) -> str:
    """The lines of ``stmt``, which must be alone on them, without its indentation."""
    rest = lines[_end_line(stmt) - 1][stmt.end_col_offset:].strip()
    if lines[stmt.lineno - 1][:stmt.col_offset].strip() or (rest and rest[0] != "#"):
        raise ValueError(f"line {stmt.lineno}: a statement to copy must be alone on its lines")
    out = []
    for line in lines[stmt.lineno - 1:stmt.end_lineno]:
        blank = len(line) - len(line.lstrip())
        out.append(line[min(blank, stmt.col_offset):])
    return "\n".join(out)


class _Template:
    """One statement's (or expression's) text with slots for the names a copy renames:
    ``pieces`` of text between the ``slots`` (the original names). A slot is a whole name
    token that is a variable (not an attribute after a dot; not in a comment or string), so
    filling it with another name, or a non-negative number, changes nothing else."""

    def __init__(self, text: str, names: frozenset[str]) -> None:
        starts = [0]
        for line in text.split("\n"):
            starts.append(starts[-1] + len(line) + 1)
        self.pieces: list[str] = []
        self.slots: list[str] = []
        at, previous = 0, None
        for tok in tokenize.generate_tokens(io.StringIO(text).readline):
            if tok.type == tokenize.NAME and tok.string in names and previous != ".":
                begin = starts[tok.start[0] - 1] + tok.start[1]
                self.pieces.append(text[at:begin])
                self.slots.append(tok.string)
                at = begin + len(tok.string)
            if tok.type not in (tokenize.NL, tokenize.NEWLINE, tokenize.COMMENT):
                previous = tok.string
        self.pieces.append(text[at:])

    def fill(self, values: dict[str, str]) -> str:
        out = [self.pieces[0]]
        for name, piece in zip(self.slots, self.pieces[1:]):
            out += (values[name], piece)
        return "".join(out)


@dataclass(frozen=True)
class _Statement:
    template: _Template
    stored: frozenset[str]  # the names it assigns
    single: str | None  # its target when it is a top-level ``name = value``
    reads: frozenset[str]  # the names its value reads (when ``single``)


@dataclass(frozen=True)
class _Inlinable:
    """A function :func:`expand` can inline: statements (branches allowed) and at most one
    ``return``, its last statement; no nested scopes or keyword arguments."""

    params: tuple[str, ...]
    body: tuple[_Statement, ...]
    returns: _Template | None
    returned: tuple[str | None, ...]  # the returned names (None: not a name)
    rebound: frozenset[str]  # parameters the body assigns
    once: frozenset[str]  # names assigned exactly once, at the top level (may be hoisted)
    free: frozenset[str]  # names it reads and never assigns, parameters aside (globals)
    words: frozenset[str]  # every word of its source

    @classmethod
    def parse(cls, name: str, source: str) -> _Inlinable:
        fn = next(n for n in ast.parse(source).body if isinstance(n, ast.FunctionDef))
        lines = source.split("\n")
        args = fn.args
        if args.posonlyargs or args.vararg or args.kwonlyargs or args.kwarg or args.defaults:
            raise ValueError(f"{name}: only plain positional parameters can be inlined")
        body = list(fn.body)
        if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
            body = body[1:]  # the docstring
        returns = (cast(ast.Return, body.pop()).value
                   if body and isinstance(body[-1], ast.Return) else None)
        unsupported = (ast.Return, ast.FunctionDef, ast.Lambda, ast.Global, ast.Nonlocal,
                       ast.ListComp, ast.SetComp, ast.DictComp, ast.GeneratorExp, ast.Yield,
                       ast.Break, ast.Continue, ast.keyword, ast.NamedExpr, ast.JoinedStr)
        nodes = [n for stmt in body for n in ast.walk(stmt)]
        for node in nodes:
            if isinstance(node, unsupported):
                raise ValueError(f"{name}: a {type(node).__name__} cannot be inlined (one "
                                 "return, as the last statement, no nested scopes)")
        params = tuple(a.arg for a in args.args)
        stored = Counter(n.id for n in nodes
                         if isinstance(n, ast.Name) and not isinstance(n.ctx, ast.Load))
        read = {n.id for n in nodes if isinstance(n, ast.Name)}
        if returns is not None:
            read |= {n.id for n in ast.walk(returns) if isinstance(n, ast.Name)}
        renamed = frozenset(stored) | frozenset(params)
        statements = []
        for stmt in body:
            single = (stmt.targets[0].id if isinstance(stmt, ast.Assign)
                      and len(stmt.targets) == 1 and isinstance(stmt.targets[0], ast.Name)
                      else None)
            statements.append(_Statement(
                template=_Template(_statement_text(lines, stmt), renamed),
                stored=frozenset(n.id for n in ast.walk(stmt) if isinstance(n, ast.Name)
                                 and not isinstance(n.ctx, ast.Load)),
                single=single,
                reads=frozenset(n.id for n in ast.walk(stmt.value) if isinstance(n, ast.Name))
                if single and isinstance(stmt, ast.Assign) else frozenset()))
        top = Counter(s.single for s in statements if s.single)
        items = returns.elts if isinstance(returns, ast.Tuple) else [returns]
        returned = tuple(e.id if isinstance(e, ast.Name) else None for e in items)
        return cls(params=params, body=tuple(statements), returned=returned,
                   returns=None if returns is None
                   else _Template(_segment(lines, returns), renamed),
                   rebound=frozenset(stored) & set(params),
                   once=frozenset(v for v, k in top.items() if k == stored[v] == 1),
                   free=frozenset(read - set(stored) - set(params)),
                   words=frozenset(_WORD.findall(source)))


class _Expander:
    """The state of one :func:`expand` pass (see there)."""

    def __init__(self, functions: dict[str, str], invariant: set[str], tag: str) -> None:
        self.functions = {name: _Inlinable.parse(name, src) for name, src in functions.items()}
        self.order = list(functions)
        self.invariant = invariant
        self.tag = tag
        self.taken: set[str] = set().union(*(f.words for f in self.functions.values()))
        self.copies = 0
        self.lines: list[str] = []

    def fresh(self, base: str) -> str:
        """``base``, or ``base_k`` for the first k that makes it a word used nowhere yet."""
        name, k = base, 0
        while name in self.taken:
            k += 1
            name = f"{base}_{k}"
        self.taken.add(name)
        return name

    def run(self, text: str) -> str:
        tree = ast.parse(text)
        self.taken |= set(_WORD.findall(text))  # (a superset of the names: words of comments)
        lines = self.lines = text.split("\n")
        edits: list[tuple[int, int, list[str]]] = []
        for fn in tree.body:
            if isinstance(fn, ast.FunctionDef):
                scope = {"assigned": _assigned(fn.body) | {a.arg for a in fn.args.args},
                         "hoisted": {}, "first": {}}
                self.block(fn.body, scope, True, lines, edits)
        for first, last, new in sorted(edits, reverse=True):
            lines[first - 1:last] = new
        return "\n".join(lines)

    def block(self, stmts: list[ast.stmt], scope: dict, top: bool, lines: list[str],
              edits: list[tuple[int, int, list[str]]]) -> None:
        for stmt in stmts:
            call, target = None, None
            if isinstance(stmt, ast.Expr):
                call = stmt.value
            elif isinstance(stmt, ast.Assign) and len(stmt.targets) == 1 and (
                    isinstance(stmt.targets[0], ast.Name) or (
                        isinstance(stmt.targets[0], ast.Tuple)
                        and all(isinstance(t, ast.Name) for t in stmt.targets[0].elts))):
                call, target = stmt.value, stmt.targets[0]
            if (isinstance(call, ast.Call) and isinstance(call.func, ast.Name)
                    and call.func.id in self.functions):
                if (lines[stmt.lineno - 1][:stmt.col_offset].strip()
                        or lines[_end_line(stmt) - 1][stmt.end_col_offset:].strip()):
                    raise ValueError(f"line {stmt.lineno}: a call to inline must be a "
                                     "statement of its own lines")
                indent = " " * stmt.col_offset
                new = self.inline(call, target, scope, top)
                edits.append((stmt.lineno, _end_line(stmt),
                              [indent + line for s in new for line in s.split("\n")]))
                continue
            for field in ("body", "orelse", "finalbody"):
                inner = getattr(stmt, field, None)
                if isinstance(inner, list) and not isinstance(stmt, ast.FunctionDef):
                    self.block(inner, scope, False, lines, edits)
            for handler in getattr(stmt, "handlers", ()):
                self.block(handler.body, scope, False, lines, edits)

    def inline(self, call: ast.Call, target: ast.expr | None, scope: dict, top: bool
               ) -> list[str]:
        name = cast(ast.Name, call.func).id  # block() inlines only calls of a name
        fn = self.functions[name]
        if call.keywords or len(call.args) != len(fn.params) or any(
                isinstance(a, ast.Starred) for a in call.args):
            raise ValueError(f"{name}: the call at line {call.lineno} does not match "
                             f"({', '.join(fn.params)})")
        shadowed = fn.free & scope["assigned"]
        if shadowed:
            raise ValueError(f"{name}: the caller assigns {', '.join(sorted(shadowed))}, "
                             f"which {name} reads as a global")
        if target is not None and fn.returns is None:
            raise ValueError(f"{name}: returns nothing to assign")
        self.copies += 1
        out: list[str] = []
        values: dict[str, str] = {}
        # block() passes a name or a tuple of names
        targets = ([cast(ast.Name, t).id for t in target.elts] if isinstance(target, ast.Tuple)
                   else [cast(ast.Name, target).id] if target is not None else [])
        names = [a.id for a in call.args if isinstance(a, ast.Name)]
        for param, arg in zip(fn.params, call.args):
            if isinstance(arg, ast.Name) and param not in fn.rebound:
                values[param] = arg.id  # a name stands for itself
            elif (isinstance(arg, ast.Name) and names.count(arg.id) == 1
                  and targets.count(arg.id) == 1 and fn.returned.count(param) == 1
                  and len(targets) == len(fn.returned)
                  and fn.returned[targets.index(arg.id)] == param):
                # a parameter the body assigns and returns into the very variable passed for
                # it (c0 = probe(..., c0)): that variable can be the parameter throughout
                values[param] = arg.id
            elif (isinstance(arg, ast.Constant) and type(arg.value) in (int, float)
                  and 0 <= cast(float, arg.value) < math.inf and param not in fn.rebound):
                values[param] = repr(arg.value)  # so does a number (a negative one is bound)
            else:  # evaluated once, before the body, as a call would
                values[param] = self.fresh(f"{param}_{self.tag}{self.copies}")
                text = _segment(self.lines, arg)
                atom = isinstance(arg, (ast.Name, ast.Constant))
                out.append(f"{values[param]} = {text if atom else f'({text})'}")
        invariant = {param for param, arg in zip(fn.params, call.args)
                     if param not in fn.rebound and isinstance(arg, ast.Name)
                     and arg.id in self.invariant}
        first = name not in scope["hoisted"]
        hoisted: dict[str, str] = scope["hoisted"].setdefault(name, {})
        if first:
            scope["first"][name] = {p: values[p] for p in invariant}
        elif hoisted and any(p not in invariant or values[p] != ident
                             for p, ident in scope["first"][name].items()):
            raise ValueError(f"{name}: the call at line {call.lineno} passes other values "
                             "for the parameters its hoisted statements read")
        values.update(hoisted)
        for stmt in fn.body:
            if stmt.single in hoisted:
                continue  # computed where the first copy stands
            if (first and top and stmt.single in fn.once
                    and all(v in hoisted or v in invariant or v in fn.free
                            for v in stmt.reads)):
                hoisted[stmt.single] = values[stmt.single] = self.fresh(
                    f"{stmt.single}_h{self.tag}{self.order.index(name)}")
            for v in sorted(stmt.stored - values.keys()):
                values[v] = self.fresh(f"{v}_{self.tag}{self.copies}")
            out.append(_fold_offsets(stmt.template.fill(values)))
        if target is not None and fn.returns is not None:  # (no returns with a target raised)
            value = _fold_offsets(fn.returns.fill(values))
            if value.replace("(", "").replace(")", "") != _segment(self.lines, target):
                out.append(f"{_segment(self.lines, target)} = {value}")
        return out


def _assigned(stmts: list[ast.stmt]) -> set[str]:
    """The names ``stmts`` assign (at any depth), without walking their expressions."""
    out: set[str] = set()
    for stmt in stmts:
        targets = {ast.Assign: lambda s: s.targets, ast.AugAssign: lambda s: [s.target],
                   ast.AnnAssign: lambda s: [s.target], ast.For: lambda s: [s.target],
                   ast.With: lambda s: [i.optional_vars for i in s.items if i.optional_vars]}
        for kind, get in targets.items():
            if isinstance(stmt, kind):
                out |= {n.id for t in get(stmt) for n in ast.walk(t) if isinstance(n, ast.Name)}
        if isinstance(stmt, (ast.FunctionDef, ast.ClassDef)):
            out.add(stmt.name)
            continue
        for field in ("body", "orelse", "finalbody"):
            inner = getattr(stmt, field, None)
            if isinstance(inner, list):
                out |= _assigned(inner)
        for handler in getattr(stmt, "handlers", ()):
            out |= _assigned(handler.body)
    return out


_OFFSET = re.compile(r"\[(\d+) \+ (\d+)\]")


def _fold_offsets(text: str) -> str:
    """``W[128 + 3]`` as ``W[131]`` (a subscript that is a sum of two integer literals)."""
    return _OFFSET.sub(lambda m: f"[{int(m[1]) + int(m[2])}]", text)


def expand(text: str, functions: dict[str, str], invariant: set[str], tag: str = "") -> str:
    """``text`` with each statement that calls one of ``functions`` (name -> source), alone or
    assigned to names (``a, b = f(x)``), replaced by the function's body. Exact by
    construction, whatever the arguments: the body is read as a syntax tree and written back
    (``ast.unparse``) with its parameters and locals as slots, and only names or non-negative
    numbers fill a slot; any other argument (``th + a``, ``-1.0``, ``W[3] * h``) is first
    bound to a new name, once, as a call evaluates it. Every name the body assigns gets a name
    of its own per copy (``x`` of the third copy is ``x_<tag>3``, with a further suffix when
    the text or a body already has that word: a copy can neither read nor overwrite a name of
    the caller or of another copy); a body's globals must not be assigned by the caller. The
    returned value is assigned to the call's targets; a literal offset ``y[yo + 3]`` with
    ``yo = 128`` becomes ``W[131]``. A top-level assignment that depends only on ``invariant``
    names (arguments that do not change through the text: p, u, the mode), globals and
    earlier such values is computed once, where the first copy of its function stands
    (``x_h<tag><k>``). Only the calls' lines change; the rest of ``text`` stays as it is.

    The step calls the vector field and the stage probe twelve times each. Numba's own
    inlining of them (inline="always") took a quarter of the module's compile time; the
    expanded text compiles to the same arithmetic, and the parameters, inputs and mode
    factors are read once per step instead of once per stage."""
    return _Expander(functions, invariant, tag).run(text)
