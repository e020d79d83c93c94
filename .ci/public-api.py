#!/usr/bin/env python3
"""The public API of esgm's library crates, one item a line, from rustdoc's JSON.

Why: an API change should be a reviewed diff (issue 41). `.ci/public-api` builds each
crate's rustdoc JSON, runs this on it, and compares the result with the committed list
in `api/<crate>.txt`; `.ci/public-api --bless` rewrites the lists after an intended
change. cargo-public-api does the same job, but needs a nightly toolchain that this
machine cannot download; rustdoc's JSON is read here directly.

Each line is an item at the path a user names it by (a re-export is listed where it is
re-exported, not where it is defined), with its kind and, for functions, its
signature: `fn esgm_shm::connect(domain: &str) -> Result<ShmEsgm, ConnectError>`.
Methods of a type follow it; trait implementations are named, derived and blanket ones
left out (they follow from the type). Items hidden with `#[doc(hidden)]` are not API.

Usage: public-api.py CRATE.json [CRATE.json...] writes the lists on stdout, one section
per crate (the caller splits them into files).
"""

import json
import sys

KINDS = {
    "module": "mod",
    "struct": "struct",
    "enum": "enum",
    "trait": "trait",
    "function": "fn",
    "constant": "const",
    "static": "static",
    "type_alias": "type",
    "macro": "macro",
    "proc_macro": "proc_macro",
    "union": "union",
    "trait_alias": "trait",
}

# Traits whose implementations say nothing a reader must review: derived or marker.
QUIET_TRAITS = {
    "Clone", "Copy", "Debug", "PartialEq", "Eq", "PartialOrd", "Ord", "Hash", "Default",
    "Send", "Sync", "Unpin", "UnwindSafe", "RefUnwindSafe", "Freeze", "StructuralPartialEq",
    "Serialize", "Deserialize", "Archive", "CheckBytes", "Portable", "Verify",
}


class Api:
    def __init__(self, doc):
        self.doc = doc
        self.index = doc["index"]
        self.lines = set()
        self.seen = set()

    def item(self, id_):
        return self.index.get(str(id_))

    # --- types -----------------------------------------------------------------------
    def ty(self, t):
        if t is None:
            return "()"
        (kind, v), = t.items()
        if kind == "primitive":
            return v
        if kind == "generic":
            return v
        if kind == "resolved_path":
            return v["path"].split("::")[-1] + self.args(v.get("args"))
        if kind == "borrowed_ref":
            life = (v["lifetime"] + " ") if v.get("lifetime") else ""
            return "&" + life + ("mut " if v["is_mutable"] else "") + self.ty(v["type"])
        if kind == "raw_pointer":
            return ("*mut " if v["is_mutable"] else "*const ") + self.ty(v["type"])
        if kind == "slice":
            return "[" + self.ty(v) + "]"
        if kind == "array":
            return "[" + self.ty(v["type"]) + "; " + str(v["len"]) + "]"
        if kind == "tuple":
            return "(" + ", ".join(self.ty(x) for x in v) + ")"
        if kind == "impl_trait":
            return "impl " + " + ".join(self.bound(b) for b in v)
        if kind == "dyn_trait":
            return "dyn " + " + ".join(
                p["trait"]["path"].split("::")[-1] + self.args(p["trait"].get("args"))
                for p in v["traits"]
            )
        if kind == "qualified_path":
            return "<" + self.ty(v["self_type"]) + ">::" + v["name"]
        if kind == "function_pointer":
            sig = v["sig"]
            ins = ", ".join(self.ty(x[1]) for x in sig["inputs"])
            out = sig.get("output")
            return "fn(" + ins + ")" + (" -> " + self.ty(out) if out else "")
        if kind == "infer":
            return "_"
        return kind

    def args(self, a):
        if not a:
            return ""
        if "angle_bracketed" in a:
            parts = []
            for x in a["angle_bracketed"]["args"]:
                if "type" in x:
                    parts.append(self.ty(x["type"]))
                elif "lifetime" in x:
                    parts.append(x["lifetime"])
                elif "const" in x:
                    parts.append(str(x["const"].get("expr", "_")))
            for c in a["angle_bracketed"].get("constraints", []):
                binding = c.get("binding", {})
                if "equality" in binding and "type" in binding["equality"]:
                    parts.append(c["name"] + " = " + self.ty(binding["equality"]["type"]))
            return "<" + ", ".join(parts) + ">" if parts else ""
        if "parenthesized" in a:
            p = a["parenthesized"]
            out = p.get("output")
            return "(" + ", ".join(self.ty(x) for x in p["inputs"]) + ")" + (
                " -> " + self.ty(out) if out else "")
        return ""

    def bound(self, b):
        if "trait_bound" in b:
            t = b["trait_bound"]["trait"]
            return t["path"].split("::")[-1] + self.args(t.get("args"))
        if "outlives" in b:
            return b["outlives"]
        return "?"

    def sig(self, f):
        sig = f["sig"]
        ins = []
        for name, t in sig["inputs"]:
            if name == "self":
                rendered = self.ty(t)
                ins.append({"Self": "self", "&Self": "&self", "&mut Self": "&mut self"}.get(
                    rendered, "self: " + rendered))
            else:
                ins.append(name + ": " + self.ty(t))
        head = f["header"]
        prefix = ("const " if head["is_const"] else "") + ("unsafe " if head["is_unsafe"] else "")
        out = sig.get("output")
        return prefix, "(" + ", ".join(ins) + ")" + (" -> " + self.ty(out) if out else "")

    # --- items -----------------------------------------------------------------------
    def hidden(self, it):
        return any("hidden" in a for a in (it.get("attrs") or []) if isinstance(a, str)) or any(
            isinstance(a, dict) and "hidden" in json.dumps(a) for a in (it.get("attrs") or []))

    def emit(self, id_, path):
        it = self.item(id_)
        if it is None or self.hidden(it):
            return
        (kind, inner), = it["inner"].items()
        key = (id_, path)
        if key in self.seen:
            return
        self.seen.add(key)
        word = KINDS.get(kind)
        if kind == "module":
            self.lines.add("mod " + path)
            self.module(inner, path)
        elif kind == "function":
            prefix, sig = self.sig(inner)
            self.lines.add(prefix + "fn " + path + sig)
        elif kind == "struct":
            self.lines.add("struct " + path)
            k = inner.get("kind", {})
            fields = k.get("plain", {}).get("fields", []) if isinstance(k, dict) else []
            if isinstance(k, dict) and "tuple" in k:
                fields = [f for f in k["tuple"] if f is not None]
            for f in fields:
                fi = self.item(f)
                if fi and fi.get("visibility") == "public" and not self.hidden(fi):
                    self.lines.add("field " + path + "::" + fi["name"] + ": " +
                                   self.ty(fi["inner"]["struct_field"]))
            self.impls(inner.get("impls", []), path)
        elif kind == "enum":
            self.lines.add("enum " + path)
            for v in inner.get("variants", []):
                vi = self.item(v)
                if vi and not self.hidden(vi):
                    self.lines.add("variant " + path + "::" + vi["name"])
            self.impls(inner.get("impls", []), path)
        elif kind == "union":
            self.lines.add("union " + path)
            self.impls(inner.get("impls", []), path)
        elif kind == "trait":
            self.lines.add(("unsafe " if inner.get("is_unsafe") else "") + "trait " + path)
            for m in inner.get("items", []):
                mi = self.item(m)
                if mi is None or self.hidden(mi):
                    continue
                (mk, mv), = mi["inner"].items()
                if mk == "function":
                    prefix, sig = self.sig(mv)
                    self.lines.add(prefix + "fn " + path + "::" + mi["name"] + sig)
                else:
                    self.lines.add(KINDS.get(mk, mk) + " " + path + "::" + mi["name"])
        elif kind == "constant":
            self.lines.add("const " + path + ": " + self.ty(inner["type"]))
        elif kind == "static":
            self.lines.add("static " + path + ": " + self.ty(inner["type"]))
        elif kind == "type_alias":
            self.lines.add("type " + path + " = " + self.ty(inner["type"]))
        elif word:
            self.lines.add(word + " " + path)

    def impls(self, ids, path):
        for i in ids:
            im = self.item(i)
            if im is None:
                continue
            imp = im["inner"]["impl"]
            if imp.get("is_synthetic") or imp.get("blanket_impl") is not None:
                continue
            trait = imp.get("trait")
            if trait is not None:
                name = trait["path"].split("::")[-1]
                if name not in QUIET_TRAITS:
                    self.lines.add("impl " + name + self.args(trait.get("args")) + " for " + path)
                continue
            for m in imp.get("items", []):
                mi = self.item(m)
                if mi is None or mi.get("visibility") != "public" or self.hidden(mi):
                    continue
                (mk, mv), = mi["inner"].items()
                if mk == "function":
                    prefix, sig = self.sig(mv)
                    self.lines.add(prefix + "fn " + path + "::" + mi["name"] + sig)
                elif mk == "constant":
                    self.lines.add("const " + path + "::" + mi["name"] + ": " +
                                   self.ty(mv["type"]))

    def module(self, inner, path):
        for id_ in inner.get("items", []):
            it = self.item(id_)
            if it is None or it.get("visibility") != "public" or self.hidden(it):
                continue
            (kind, v), = it["inner"].items()
            if kind == "use":
                target = v.get("id")
                if v.get("is_glob"):
                    t = self.item(target) if target is not None else None
                    if t is not None and "module" in t["inner"]:
                        self.module(t["inner"]["module"], path)
                    else:
                        self.lines.add("pub use " + v["source"] + "::* in " + path)
                    continue
                name = path + "::" + v["name"]
                if target is not None and self.item(target) is not None:
                    self.emit(target, name)
                else:
                    # From another crate: listed as the re-export it is.
                    self.lines.add("pub use " + name + " = " + v["source"])
            else:
                self.emit(id_, path + "::" + it["name"])


def main():
    for file in sys.argv[1:]:
        doc = json.load(open(file))
        api = Api(doc)
        root = api.item(doc["root"])
        api.lines.add("crate " + root["name"])
        api.module(root["inner"]["module"], root["name"])
        print("#### " + root["name"])
        for line in sorted(api.lines):
            print(line)


if __name__ == "__main__":
    main()
