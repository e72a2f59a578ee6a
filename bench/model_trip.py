#!/usr/bin/env python3
"""A model's trip through the measurement code, and the size limits of src/measure/ (issue 54).

TRIP. Reads every .rs file under src/ (unit-test modules left out), finds each function and its
parameters, and follows the model from `diagnose`'s parameter `model` along the call graph: in
a function, the names that hold the model are its parameters of a model-carrying type (`Model`,
or a struct with a field of such a type, found transitively: `Fit` holds one) that were handed
the model, `self` in a method of such a type, and every `let` bound to an expression that
mentions one of them. A call is followed where an argument (or the receiver) mentions such a
name and the callee's parameter at that place is of a model-carrying type. A callee is found by
its name: in the caller's file first, then among the functions of that name in the whole tree
when exactly one (a method: one among the methods of that name whose parameter fits); a call
whose callee the program chooses as it runs (a trait's method with several implementations) is
not followed. A call by a type's path (`Type::f(...)`, `Self::f(...)`) names that type's function;
a method's receiver that is a parameter of the caller, or a field of `self`, has that one's type, and a
field whose type carries no model hands none on; a call by a
module's path (`runner::evaluate(...)`) names a function of that module's file. Each function is walked once, depth first, in the order in which the code is
written.

The walk is a list of events, the file of each: entering a callee, and coming back to the
caller's file after it. Consecutive events in one file are one STAY; a stay in a file that the
trip had already left is a RETURN. Printed: stays, files, returns, and the stays per file.

LIMITS (--limits). Every function in src/measure/ (unit tests included) over 100 lines or over
6 parameters (`self` not counted), and every line over 120 characters; exits 1 if any.

Usage: bench/model_trip.py [--root DIR] [--from FILE:FUNCTION:PARAM] [--route] [--limits]
"""
import argparse, os, re, sys
from collections import Counter

MODEL = "Model"


def blank(text):
    """`text` with comments, strings and char literals replaced by spaces (lengths and lines kept)."""
    out, i, n = [], 0, len(text)
    while i < n:
        c = text[i]
        if text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
            out.append(" " * (j - i)); i = j
        elif text.startswith("/*", i):
            j, depth = i + 2, 1
            while j < n and depth:
                if text.startswith("/*", j): depth += 1; j += 2
                elif text.startswith("*/", j): depth -= 1; j += 2
                else: j += 1
            out.append(re.sub(r"[^\n]", " ", text[i:j])); i = j
        elif c == "r" and re.match(r'r#*"', text[i:i + 10]) and (i == 0 or not (text[i - 1].isalnum() or text[i - 1] == "_")):
            hashes = re.match(r'r(#*)"', text[i:]).group(1)
            end = text.find('"' + hashes, i + 2 + len(hashes))
            j = n if end < 0 else end + 1 + len(hashes)
            out.append(re.sub(r"[^\n]", " ", text[i:j])); i = j
        elif c == '"':
            j = i + 1
            while j < n and text[j] != '"':
                j += 2 if text[j] == "\\" else 1
            j += 1
            out.append('"' + re.sub(r"[^\n]", " ", text[i + 1:j - 1]) + '"'); i = j
        elif c == "'":
            m = re.match(r"'(\\.[^']*|[^\\'])'", text[i:])
            if m:
                out.append(" " * len(m.group(0))); i += len(m.group(0))
            else:
                out.append(c); i += 1
        else:
            out.append(c); i += 1
    return "".join(out)


def close(text, i, open_, shut):
    """Index just past the bracket that closes the one at `i`."""
    depth = 0
    for j in range(i, len(text)):
        if text[j] == open_: depth += 1
        elif text[j] == shut:
            depth -= 1
            if depth == 0:
                return j + 1
    return len(text)


def without_tests(code):
    """`code` (blanked) with every `#[cfg(test)]` item blanked too."""
    for m in reversed(list(re.finditer(r"#\[cfg\(test\)\]", code))):
        b = code.find("{", m.end())
        semi = code.find(";", m.end())
        if b < 0 or (0 <= semi < b):
            continue
        e = close(code, b, "{", "}")
        code = code[:m.start()] + re.sub(r"[^\n]", " ", code[m.start():e]) + code[e:]
    return code


def split_top(s):
    """`s` split at the commas outside brackets."""
    parts, depth, cur = [], 0, []
    for c in s:
        if c in "([{<": depth += 1
        elif c in ")]}>": depth -= 1
        if c == "," and depth == 0:
            parts.append("".join(cur)); cur = []
        else:
            cur.append(c)
    if "".join(cur).strip():
        parts.append("".join(cur))
    return [p.strip() for p in parts]


class Fn:
    def __init__(self, file, name, owner, params, start, end, body, line, lines):
        self.file, self.name, self.owner = file, name, owner
        self.params, self.start, self.end, self.body = params, start, end, body
        self.line, self.lines = line, lines

    def key(self):
        return f"{self.file}:{self.owner + '.' if self.owner else ''}{self.name}"


def functions(path, rel, keep_tests):
    text = open(path).read()
    code = blank(text)
    if not keep_tests:
        code = without_tests(code)
    impls = []  # (start, end, type)
    for m in re.finditer(r"\bimpl\b(?:\s*<[^{]*?>)?\s+(?:[\w:<>&' ,]+?\s+for\s+)?([A-Za-z_][\w:]*)[^{;]*\{", code):
        impls.append((m.end() - 1, close(code, m.end() - 1, "{", "}"), m.group(1).split("::")[-1]))
    out = []
    for m in re.finditer(r"\bfn\s+([A-Za-z_]\w*)\s*(<)?", code):
        i = m.end()
        if m.group(2):
            i = close(code, i - 1, "<", ">")
        p = code.find("(", i)
        if p < 0:
            continue
        pe = close(code, p, "(", ")")
        b = pe
        while b < len(code) and code[b] not in "{;":
            b += 1
        if b >= len(code) or code[b] == ";":
            continue
        e = close(code, b, "{", "}")
        owner = ""
        for s, t, ty in impls:
            if s < m.start() < t:
                owner = ty
        params = []
        for part in split_top(code[p + 1:pe - 1]):
            if re.match(r"^(&\s*('\w+\s+)?)?(mut\s+)?self\b", part):
                params.append(("self", owner))
            elif ":" in part:
                pat, ty = part.split(":", 1)
                params.append((pat.strip(), ty.strip()))
        line = code.count("\n", 0, m.start()) + 1
        lines = code.count("\n", m.start(), e) + 1
        out.append(Fn(rel, m.group(1), owner, params, m.start(), e, code[b:e], line, lines))
    structs = {}
    for m in re.finditer(r"\b(?:struct|enum)\s+([A-Za-z_]\w*)[^{;(]*\{", code):
        structs[m.group(1)] = code[m.end():close(code, m.end() - 1, "{", "}")]
    return out, structs


def load(root, keep_tests=False):
    fns, structs = [], {}
    for d, _, files in os.walk(os.path.join(root, "src")):
        for f in sorted(files):
            if f.endswith(".rs"):
                path = os.path.join(d, f)
                a, s = functions(path, os.path.relpath(path, root), keep_tests)
                fns += a
                structs.update(s)
    return fns, structs


def field_types(body):
    """The types a struct's or enum's body names: after each field's `:`, inside each variant's `(...)`."""
    types = []
    for part in split_top(body):
        part = re.sub(r"#\[[^\]]*\]", "", part).strip()
        m = re.match(r"^(?:pub(?:\([^)]*\))?\s+)?\w+\s*:(.*)$", part, re.S)
        if m:
            types.append(m.group(1))
        elif "(" in part:
            types.append(part[part.index("(") + 1:])
        elif "{" in part:
            types += field_types(part[part.index("{") + 1:part.rindex("}")])
    return types


def carriers(structs):
    """The types that hold a model: `Model`, and every struct or enum with a field of one."""
    held = {MODEL}
    grew = True
    while grew:
        grew = False
        for name, body in structs.items():
            if name not in held and any(carries(t, held) for t in field_types(body)):
                held.add(name); grew = True
    return held


def carries(ty, held):
    return any(re.search(rf"\b{t}\b", ty) for t in held)


def names_in(expr):
    return set(re.findall(r"\b[a-z_]\w*\b", expr))


def calls(body):
    """(position, callee name, is a method, receiver text, argument texts) of each call in `body`."""
    for m in re.finditer(r"(\.)?\s*\b([A-Za-z_]\w*)\s*(?:::<[^()]*?>)?\s*\(", body):
        name = m.group(2)
        if name in ("if", "while", "for", "match", "return", "Some", "Ok", "Err", "fn", "move", "in"):
            continue
        prev = body[:m.start()].rstrip()
        if prev.endswith("fn"):
            continue
        p = body.index("(", m.end() - 1)
        args = split_top(body[p + 1:close(body, p, "(", ")") - 1])
        receiver = ""
        if m.group(1):
            j = m.start() - 1
            depth = 0
            while j >= 0:
                c = body[j]
                if c in ")]}": depth += 1
                elif c in "([{":
                    if depth == 0: break
                    depth -= 1
                elif depth == 0 and not (c.isalnum() or c in "_.&*?:"):
                    break
                j -= 1
            receiver = body[j + 1:m.start()]
        else:
            # an associated function called by its type's path (`Type::f(...)`, `Self::f(...)`):
            # the receiver is the path, and the callee is that type's
            path = re.search(r"\b([A-Z]\w*)\s*::\s*$", body[:m.start()])
            module = re.search(r"\b([a-z_]\w*)\s*::\s*$", body[:m.start()])
            if path:
                receiver = path.group(1) + "::"
            elif module and module.group(1) not in ("crate", "super", "self"):
                receiver = "mod:" + module.group(1)
            else:
                receiver = ""
        yield m.start(), name, bool(m.group(1)), receiver, args


def tracked_lets(body, names):
    """`names` grown by every `let` (and `for`/closure binding) whose expression mentions one."""
    names = set(names)
    grew = True
    while grew:
        grew = False
        for m in re.finditer(r"\blet\s+(mut\s+)?([^=;]+?)(?::[^=;]*)?=([^;]*);", body):
            if names_in(m.group(3)) & names:
                new = {n for n in names_in(m.group(2)) if n not in ("mut", "ref", "_", "some", "ok")}
                if not new <= names:
                    names |= new; grew = True
        for m in re.finditer(r"\bfor\s+([^{]+?)\s+in\s+([^{]+)\{", body):
            if names_in(m.group(2)) & names:
                new = names_in(m.group(1)) - {"mut", "ref", "_"}
                if not new <= names:
                    names |= new; grew = True
    return names


def receiver_type(caller, receiver, structs):
    """The type a method's receiver names where the caller's code shows it: `self`, `self.FIELD`."""
    r = receiver.strip().lstrip("&*")
    if r == "self":
        return caller.owner
    for name, ty in caller.params:
        if name == r:
            found = re.findall(r"\b[A-Z]\w*", ty)
            return found[-1] if found else ""
    m = re.match(r"^self\.(\w+)$", r)
    if m and caller.owner in structs:
        for part in split_top(structs[caller.owner]):
            f = re.match(r"^(?:pub(?:\([^)]*\))?\s+)?(\w+)\s*:(.*)$", part.strip(), re.S)
            if f and f.group(1) == m.group(1):
                names = re.findall(r"\b[A-Z]\w*", f.group(2))
                return names[-1] if names else ""
    return ""


def resolve(fns_by_name, caller, call, at, held, structs):
    """The one function a call names, or None (unknown, or chosen as the program runs)."""
    _, name, is_method, receiver, _ = call
    if receiver.endswith("::"):
        ty = caller.owner if receiver == "Self::" else receiver[:-2]
        cands = [f for f in fns_by_name.get(name, []) if f.owner == ty]
    else:
        cands = [f for f in fns_by_name.get(name, []) if bool(f.owner) == is_method]
        if receiver.startswith("mod:"):
            module = receiver[4:]
            stem = lambda f: os.path.basename(os.path.dirname(f)) if f.endswith("/mod.rs") else os.path.basename(f)[:-3]
            cands = [f for f in cands if stem(f.file) == module] or cands
    cands = [f for f in cands if at < len(f.params) and carries(f.params[at][1], held)]
    if len(cands) > 1 and is_method:
        ty = receiver_type(caller, receiver, structs)
        if ty:
            cands = [f for f in cands if f.owner == ty] or cands
    if len(cands) > 1:
        cands = [f for f in cands if f.file == caller.file] or cands
    return cands[0] if len(cands) == 1 else None


def walk(fns, held, structs, start):
    by_name = {}
    for f in fns:
        by_name.setdefault(f.name, []).append(f)
    seen, events = set(), []

    def visit(fn, entering):
        seen.add(fn.key())
        events.append((fn.file, fn.key()))
        holds = tracked_lets(fn.body, entering)
        for call in calls(fn.body):
            _, name, is_method, receiver, args = call
            given = []
            if is_method and names_in(receiver) & holds:
                # a field of a carrier (`self.campaign`) carries the model only if its type does
                ty = receiver_type(fn, receiver, structs) if receiver.strip().lstrip("&*").startswith("self.") else ""
                if not ty or ty in held:
                    given.append(("self", 0))
            for k, a in enumerate(args):
                if names_in(a) & holds:
                    given.append(("arg", k))
            for kind, k in given:
                at = 0 if kind == "self" else k + (1 if is_method else 0)
                callee = resolve(by_name, fn, call, at, held, structs)
                if callee is None or callee.key() in seen:
                    continue
                pat = callee.params[at][0]
                visit(callee, names_in(pat) - {"mut"})
                events.append((fn.file, fn.key()))
                break

    file, fname, param = start.split(":")
    first = [f for f in fns if f.file == file and f.name == fname]
    if not first:
        sys.exit(f"no function {fname} in {file}")
    visit(first[0], {param})
    return events


def stays(events):
    out = []
    for file, _ in events:
        if not out or out[-1] != file:
            out.append(file)
    return out


def limits(root):
    fns, _ = load(root, keep_tests=True)
    bad = []
    for f in fns:
        if not f.file.startswith("src/measure/"):
            continue
        args = [p for p in f.params if p[0] != "self"]
        if f.lines > 100:
            bad.append(f"{f.file}:{f.line}: fn {f.name} runs {f.lines} lines (over 100)")
        if len(args) > 6:
            bad.append(f"{f.file}:{f.line}: fn {f.name} takes {len(args)} arguments (over 6)")
    for d, _, files in os.walk(os.path.join(root, "src/measure")):
        for name in sorted(files):
            if name.endswith(".rs"):
                path = os.path.join(d, name)
                for k, line in enumerate(open(path).read().split("\n"), 1):
                    if len(line) > 120:
                        bad.append(f"{os.path.relpath(path, root)}:{k}: line of {len(line)} characters (over 120)")
    return bad


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--root", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
    ap.add_argument("--from", dest="start", default="src/measure/diagnose/mod.rs:diagnose:model")
    ap.add_argument("--route", action="store_true", help="print every stay in order")
    ap.add_argument("--limits", action="store_true", help="check src/measure/'s function and line limits")
    a = ap.parse_args()
    if a.limits:
        bad = limits(a.root)
        print("\n".join(bad) if bad else "src/measure/: no function over 100 lines or 6 arguments, no line over 120 characters")
        print(f"{len(bad)} over the limits")
        sys.exit(1 if bad else 0)
    fns, structs = load(a.root)
    held = carriers(structs)
    events = walk(fns, held, structs, a.start)
    s = stays(events)
    if a.route:
        for k, f in enumerate(s, 1):
            print(f"{k:4}  {f}")
    per = Counter(s)
    print(f"model trip from {a.start}: {len(s)} stays in {len(per)} files, {len(s) - len(per)} returns to a file already left")
    print(f"functions entered: {len({k for _, k in events})}; model-carrying types: {', '.join(sorted(held))}")
    for f, n in per.most_common():
        print(f"  {n:3}  {f}")


if __name__ == "__main__":
    main()
