"""Text analysis shared by both engines, the query planner, and snippet highlighting.

One analyzer (tantivy's Rust pipeline: simple tokenizer -> drop tokens over 40 chars ->
lowercase -> ASCII folding -> English stop words -> Snowball English stemmer) produces the
tokens for *both* indexes, so the bm25s matrix and the tantivy index see identical terms and
identical document lengths.

Queries: any string is valid. Plain text becomes an OR of its unique analysed terms (the
paper's semantics, ranked by BM25). When the user writes query syntax -- a double-quoted
phrase, the operators AND / OR / NOT in capitals, or a leading ``+``/``-`` on a word -- the
query is parsed by a small, total (never failing) recursive-descent parser into a boolean tree
that the tantivy engine executes. Everything else (``*``, ``:``, ``NEAR``, brackets, emoji,
scripts without word breaks) is just text to the analyzer.
"""

from __future__ import annotations

import re
import threading
from dataclasses import dataclass, field

import tantivy

MAX_TOKEN_CHARS = 40
MAX_QUERY_CHARS = 200_000  # longer inputs are truncated before analysis (100 KB of text is fine)
MAX_QUERY_TERMS = 64  # unique terms kept from a free-text query (the most selective ones)
MAX_STRUCT_LEAVES = 64
MAX_DEPTH = 16


def build_analyzer() -> tantivy.TextAnalyzer:
    return (
        tantivy.TextAnalyzerBuilder(tantivy.Tokenizer.simple())
        .filter(tantivy.Filter.remove_long(MAX_TOKEN_CHARS))
        .filter(tantivy.Filter.lowercase())
        .filter(tantivy.Filter.ascii_fold())
        .filter(tantivy.Filter.stopword("english"))
        .filter(tantivy.Filter.stemmer("english"))
        .build()
    )


_local = threading.local()


def analyzer() -> tantivy.TextAnalyzer:
    """A per-thread analyzer instance (cheap to build, not shared across threads)."""
    inst = getattr(_local, "analyzer", None)
    if inst is None:
        inst = _local.analyzer = build_analyzer()
    return inst


def analyze(text: str) -> list[str]:
    """Index/query terms of a text, in order (stop words removed, stemmed)."""
    if not text:
        return []
    return analyzer().analyze(text)


def unique(seq: list[str]) -> list[str]:
    return list(dict.fromkeys(seq))


# --------------------------------------------------------------------------------------------
# Query plans
# --------------------------------------------------------------------------------------------


@dataclass
class Node:
    """A node of a structured query: op is TERM, PHRASE, AND, OR, NOT or MUST."""

    op: str
    children: list["Node"] = field(default_factory=list)
    tokens: list[tuple[int, str]] = field(default_factory=list)  # (position, term) for TERM/PHRASE


@dataclass
class QueryPlan:
    kind: str  # "empty", "free" or "structured"
    terms: list[str] = field(default_factory=list)  # free: unique analysed terms, in order
    tree: Node | None = None  # structured
    highlight: set[str] = field(default_factory=set)


_PHRASE = re.compile(r'"[^"]*[^\W_][^"]*"')
_OPERATOR = re.compile(r"(?:^|[\s(])(?:AND|OR|NOT)(?=[\s(\"]|$)")
_SIGN = re.compile(r"(?:^|[\s(])[+-][\"\w]")


def looks_structured(query: str) -> bool:
    """True when the user wrote query syntax (phrases, AND/OR/NOT, +/-)."""
    return bool(_PHRASE.search(query) or _OPERATOR.search(query) or _SIGN.search(query))


def plan_query(query: object) -> QueryPlan:
    """Turn any input into a query plan. Never raises."""
    if query is None:
        return QueryPlan("empty")
    text = query if isinstance(query, str) else str(query)
    if len(text) > MAX_QUERY_CHARS:
        text = text[:MAX_QUERY_CHARS]
    # Lone surrogates cannot be encoded for the Rust analyzer; drop them.
    text = text.encode("utf-8", "ignore").decode("utf-8")
    if not text.strip():
        return QueryPlan("empty")
    if looks_structured(text):
        tree = _Parser(text).parse()
        if tree is not None:
            hl: set[str] = set()
            _collect_positive(tree, hl)
            return QueryPlan("structured", tree=tree, highlight=hl)
        return QueryPlan("empty")
    terms = unique(analyze(text))
    if not terms:
        return QueryPlan("empty")
    return QueryPlan("free", terms=terms, highlight=set(terms))


def _collect_positive(node: Node, out: set[str]) -> None:
    if node.op == "NOT":
        return
    for _, term in node.tokens:
        out.add(term)
    for child in node.children:
        _collect_positive(child, out)


class _Parser:
    """Total recursive-descent parser: every input yields a tree or None, never an error.

    Grammar (juxtaposition means OR, AND binds tighter):
        or   := and (["OR"] and)*
        and  := unary ("AND" unary)*
        unary:= "NOT" unary | "-" unary | "+" unary | primary
        primary := "(" or ")" | PHRASE | WORD
    """

    def __init__(self, text: str) -> None:
        self.lex = self._lex(text)
        self.i = 0
        self.leaves = 0
        self.depth = 0

    @staticmethod
    def _lex(text: str) -> list[tuple[str, str]]:
        out: list[tuple[str, str]] = []
        i, n = 0, len(text)
        while i < n:
            c = text[i]
            if c.isspace():
                i += 1
            elif c == '"':
                j = text.find('"', i + 1)
                j = n if j < 0 else j
                out.append(("PHRASE", text[i + 1 : j]))
                i = j + 1
            elif c in "()":
                out.append(("(" if c == "(" else ")", c))
                i += 1
            elif c in "+-" and i + 1 < n and not text[i + 1].isspace() and (i == 0 or text[i - 1].isspace() or text[i - 1] == "("):
                out.append(("SIGN", c))
                i += 1
            else:
                j = i
                while j < n and not text[j].isspace() and text[j] not in '"()':
                    j += 1
                word = text[i:j]
                out.append(("OP", word) if word in ("AND", "OR", "NOT") else ("WORD", word))
                i = j
        return out

    def peek(self) -> tuple[str, str] | None:
        return self.lex[self.i] if self.i < len(self.lex) else None

    def parse(self) -> Node | None:
        nodes: list[Node] = []
        while self.peek() is not None:
            node = self.or_expr()
            if node is not None:
                nodes.append(node)
            tok = self.peek()
            if tok is not None and tok[0] == ")":  # stray closing parenthesis
                self.i += 1
        return _simplify(Node("OR", nodes))

    def or_expr(self) -> Node | None:
        children: list[Node] = []
        while True:
            tok = self.peek()
            if tok is None or tok[0] == ")":
                break
            if tok == ("OP", "OR"):
                self.i += 1
                continue
            node = self.and_expr()
            if node is not None:
                children.append(node)
        return _simplify(Node("OR", children))

    def and_expr(self) -> Node | None:
        children: list[Node] = []
        node = self.unary()
        if node is not None:
            children.append(node)
        while self.peek() == ("OP", "AND"):
            self.i += 1
            nxt = self.peek()
            if nxt is None or nxt[0] == ")":
                break
            node = self.unary()
            if node is not None:
                children.append(node)
        if len(children) <= 1:
            return children[0] if children else None
        return Node("AND", children)

    def unary(self) -> Node | None:
        negate, must = False, False
        while True:  # prefix operators, iteratively (no recursion on "NOT NOT NOT ...")
            tok = self.peek()
            if tok is None or tok[0] == ")":
                return None
            if tok == ("OP", "NOT") or tok == ("SIGN", "-"):
                negate = not negate
            elif tok == ("SIGN", "+"):
                must = True
            elif tok[0] == "OP":  # AND/OR where an operand is expected: skip it
                self.i += 1
                return None
            else:
                break
            self.i += 1
        node = self.primary()
        if node is None:
            return None
        if negate:
            return Node("NOT", [node])
        return Node("MUST", [node]) if must else node

    def primary(self) -> Node | None:
        kind, value = self.lex[self.i]
        self.i += 1
        if kind == "(":
            if self.depth >= MAX_DEPTH:
                return None  # absurd nesting: treat the parenthesis as text
            self.depth += 1
            node = self.or_expr()
            self.depth -= 1
            if self.peek() is not None and self.peek()[0] == ")":
                self.i += 1
            return node
        if kind == ")":
            return None
        if self.leaves >= MAX_STRUCT_LEAVES:
            return None
        if kind in ("PHRASE", "WORD"):
            tokens = analyzer().pre_tokenize(value).tokens if value else []
            pairs = [(t.position, t.text) for t in tokens]
            if not pairs:
                return None
            self.leaves += 1
            base = pairs[0][0]
            pairs = [(p - base, t) for p, t in pairs]
            return Node("PHRASE" if len(pairs) > 1 else "TERM", tokens=pairs)
        return None  # SIGN alone, OP handled elsewhere


def _simplify(node: Node) -> Node | None:
    kids = [k for k in node.children if k is not None]
    if not kids:
        return None
    if len(kids) == 1 and node.op in ("OR", "AND"):
        return kids[0]
    node.children = kids
    return node


# --------------------------------------------------------------------------------------------
# Snippets
# --------------------------------------------------------------------------------------------

_WORD = re.compile(r"[^\W_]+")
# Snowball English's exceptional forms whose stem is not a prefix: lying -> lie, skies -> sky.
_IRREGULAR = {"lie": "ly", "die": "dy", "tie": "ty", "sky": "sk"}
_ASCII_WORD = re.compile(r"[a-z0-9]+")  # the same words in lower-cased ASCII text, 3x faster
SNIPPET_CHARS = 240
SNIPPET_SCAN_CHARS = 50_000


class Highlighter:
    """Builds a snippet of the best window of a text with the matched terms highlighted.

    A word matches when its analysed form (same analyzer as the index) is a query term, so
    "Coughing" is highlighted for the query "cough". Word -> term results are cached, so each
    distinct word is analysed once per process. The window is the ~240-character span with the most distinct terms.
    """

    def __init__(self, start: str = "**", end: str = "**", chars: int = SNIPPET_CHARS) -> None:
        self.start, self.end, self.chars = start, end, chars
        self._cache: dict[str, str | None] = {}
        self._prefix_cache: dict[frozenset, tuple[str, ...]] = {}
        self._lock = threading.Lock()

    def _term(self, word: str) -> str | None:
        term = self._cache.get(word, "")
        if term != "":
            return term
        toks = analyze(word)
        term = toks[0] if len(toks) == 1 else None
        if len(self._cache) > 200_000:
            with self._lock:
                self._cache.clear()
        self._cache[word] = term
        return term

    def _prefixes(self, terms: set[str]) -> tuple[str, ...]:
        """Prefixes that every word stemming to one of `terms` starts with.

        The Snowball English stemmer only rewrites the end of a word: it drops suffixes, turns a
        final y into i, adds back a final e, and replaces suffixes by shorter ones (-ational ->
        -ate, -biliti -> -ble, -enci -> -ence). A stem therefore shares all but at most its last
        two letters with its word ("any" -> "ani"); prefixes keep at least two letters. The few
        irregular forms of the stemmer (lying, dying, tying, skies) are added explicitly.
        """
        key = frozenset(terms)
        pre = self._prefix_cache.get(key)
        if pre is None:
            cut = {t if len(t) <= 2 else t[: max(2, len(t) - 2)] for t in terms if t}
            cut |= {_IRREGULAR[t] for t in terms if t in _IRREGULAR}
            pre = tuple(sorted(p for p in cut if not any(p != q and p.startswith(q) for q in cut)))
            if len(self._prefix_cache) > 1024:
                self._prefix_cache.clear()
            self._prefix_cache[key] = pre
        return pre

    def matches(self, text: str, terms: set[str]) -> list[tuple[int, int, str]]:
        """(start, end, term) of every word of `text` whose analysed form is one of `terms`."""
        if not terms:
            return []
        out = []
        low = text.lower()
        if text.isascii() and len(low) == len(text):
            # Fast path: str.find of each term's prefix (C speed); only words starting there are
            # analysed (cached), so a passage costs a few microseconds.
            cache = self._cache
            for pre in self._prefixes(terms):
                i = low.find(pre)
                while i >= 0:
                    if i and low[i - 1].isalnum():  # not the start of a word
                        i = low.find(pre, i + 1)
                        continue
                    j = _ASCII_WORD.match(low, i).end()
                    w = low[i:j]
                    t = cache.get(w, "")
                    if t == "":
                        t = self._term(w)
                    if t is not None and t in terms:
                        out.append((i, j, t))
                    i = low.find(pre, j)
            out.sort()
            return out
        return self.matches_slow(text, terms)

    def matches_slow(self, text: str, terms: set[str]) -> list[tuple[int, int, str]]:
        """Reference implementation: analyse every word."""
        out = []
        for m in _WORD.finditer(text):
            t = self._term(m.group().lower())
            if t in terms:
                out.append((m.start(), m.end(), t))
        return out

    def snippet(self, text: str, terms: set[str]) -> str:
        if not text:
            return ""
        scan = text[:SNIPPET_SCAN_CHARS]
        found = self.matches(scan, terms)
        L = self.chars
        ws = 0
        if found:  # sliding window over the matches: most distinct terms, then most matches
            best = (-1, -1)
            counts: dict[str, int] = {}
            n, j = len(found), 0
            for i, (s, _e, t) in enumerate(found):
                lo = max(0, s - 40)
                if j < i:
                    j = i
                while j < n and found[j][1] <= lo + L:
                    tj = found[j][2]
                    counts[tj] = counts.get(tj, 0) + 1
                    j += 1
                key = (len(counts), j - i)
                if key > best:
                    best, ws = key, lo
                if j > i:
                    c = counts[t] - 1
                    if c:
                        counts[t] = c
                    else:
                        del counts[t]
        we = min(len(text), ws + L)
        if ws > 0:  # snap to word boundaries, widening the window
            cut = text.rfind(" ", max(0, ws - 30), ws)
            ws = cut + 1 if cut >= 0 else ws
        if we < len(text):
            cut = text.find(" ", we, we + 30)
            we = cut if cut >= 0 else we
        parts: list[str] = []
        pos = ws
        # Marker characters already in the text (markdown bold) would garble the highlighting.
        clean = (lambda x: x.replace(self.start, "").replace(self.end, "")) if (
            self.start in text or self.end in text) else (lambda x: x)
        for s, e, _t in found:
            if s < ws or e > we:
                continue
            parts.append(clean(text[pos:s]))
            parts.append(f"{self.start}{text[s:e]}{self.end}")
            pos = e
        parts.append(clean(text[pos:we]))
        out = " ".join("".join(parts).split())
        if ws > 0:
            out = "… " + out
        if we < len(text):
            out = out + " …"
        return out
