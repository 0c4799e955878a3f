"""SpaceEx import (sspaceex 0.2 XML + .cfg, the ARCH-COMP AFF interchange format).

The XML is read safely with its lines (:mod:`.xmltree`), into components (:mod:`.components`);
the cfg's system is instantiated and composed (:mod:`.compose`), and converted into the same
plain documents the YAML loaders read (:mod:`.convert`). The ordinary loaders then build and
check the :class:`~reach.model.automaton.HybridAutomaton` and the property, so an imported model
and its YAML export are the same automaton by construction.
"""

from __future__ import annotations

from pathlib import Path

from reach.errors import InputError
from reach.model.spaceex.cfg import Config, read_cfg
from reach.model.spaceex.components import read_document
from reach.model.spaceex.compose import compose, instantiate
from reach.model.spaceex.convert import DocumentBuilder, Documents
from reach.model.spaceex.formula import Loc
from reach.model.spaceex.xmltree import read_xml


def default_cfg(xml_path) -> Path:
    """The cfg next to the model with the same stem (``bball.xml`` -> ``bball.cfg``)."""
    path = Path(xml_path).with_suffix(".cfg")
    if not path.is_file():
        raise InputError("no .cfg given and none with the same name next to the model "
                         "(the cfg holds the system, initial set and horizon)", str(xml_path))
    return path


def documents(xml_path, cfg_path=None, name: str | None = None) -> Documents:
    """The model and property documents of a SpaceEx model and its cfg."""
    xml_path = Path(xml_path)
    cfg_path = Path(cfg_path) if cfg_path is not None else default_cfg(xml_path)
    cfg = read_cfg(cfg_path)
    doc = read_document(read_xml(xml_path), str(xml_path))
    system = (cfg.text("system") or "").strip()
    if not system:
        raise InputError("no 'system'", str(cfg_path), line=1)
    flat = instantiate(doc, system, cfg.line("system"), cfg.file)
    builder = DocumentBuilder(flat, str(xml_path), cfg, name or cfg_path.stem)
    compose(flat, _initial_locations(builder, cfg))
    return builder.build()


def _initial_locations(builder: DocumentBuilder, cfg: Config):
    """Allowed location names per instance from the ``loc()`` terms of ``initially``."""
    allowed = [None] * len(builder.flat.instances)
    for term in builder.cfg_formula("initially", required=True)[:1]:
        for atom in term:
            if isinstance(atom, Loc):
                i = builder.location_of(atom, "initially")
                if allowed[i] is not None and atom.location not in allowed[i]:
                    raise _contradiction(builder, cfg, i, next(iter(allowed[i])), atom.location)
                allowed[i] = {atom.location}
    return allowed


def _contradiction(builder: DocumentBuilder, cfg: Config, i: int, first: str, second: str) -> InputError:
    """Two ``loc()`` terms of ``initially`` that put instance ``i`` in two locations at once."""
    instance = builder.flat.instances[i]
    name = instance.path or instance.component.id
    return InputError(f"the initial set is empty (no location of {name} satisfies loc({name}) == {first} "
                      f"and loc({name}) == {second})", cfg.file, "initially", cfg.line("initially"))


def load_spaceex(xml_path, cfg_path=None):
    """``(model, properties)``: the HybridAutomaton and the list of bound-ready properties
    (``reach.spec`` Property objects) of the cfg's forbidden set (empty if it has none)."""
    from reach.model.loader import model_from_doc
    from reach.spec.properties import properties_from_doc
    from reach.yamlio import Doc

    docs = documents(xml_path, cfg_path)
    model = model_from_doc(Doc(docs.model, docs.model_lines, str(xml_path)))
    props = []
    if docs.properties is not None:
        props = properties_from_doc(Doc(docs.properties, docs.property_lines, str(cfg_path or default_cfg(xml_path))))
    return model, props, docs


def write_yaml(docs: Documents, out_dir, option: str = "--out") -> tuple[Path, Path | None]:
    """Write ``out_dir/models/NAME.yaml`` and ``out_dir/properties/NAME.yaml`` (if the cfg
    forbids anything); NAME is the cfg's file name, sanitised (:func:`_fallback_name` if nothing
    is left). The folder ``out_dir`` is the user's (``option`` names it); ``models`` and
    ``properties`` below it are the tool's, and one that is a symbolic link is bad input (a write
    through it would land wherever it points)."""
    import yaml

    from reach.errors import InputError
    from reach.paths import printable, safe_name, writable_file

    safe = safe_name(str(docs.model["name"]), "") or _fallback_name(str(docs.model["name"]))
    out = Path(out_dir)
    for sub in ("models", "properties"):
        if (out / sub).is_symlink():
            raise InputError(f"{printable(out / sub)} is a symbolic link: not written through", field=option)
    model_path = writable_file(out / "models" / f"{safe}.yaml", option)     # both checked before
    prop_path = None if docs.properties is None else writable_file(out / "properties" / f"{safe}.yaml", option)
    header = f"# {docs.model['description']}\n"
    model_path.write_text(header + yaml.safe_dump(docs.model, sort_keys=False, width=120))
    if prop_path is not None:
        prop_path.write_text(f"# the forbidden set of {docs.model['notes']['config']}\n"
                             + yaml.safe_dump(docs.properties, sort_keys=False, width=120))
    return model_path, prop_path


def _fallback_name(name: str) -> str:
    """The file name for a cfg whose name leaves nothing once made safe (``..cfg``, ``%.cfg``):
    ``model_`` and the first digits of the name's SHA-256, so two such cfgs write two files."""
    import hashlib

    return "model_" + hashlib.sha256(name.encode("utf-8", "surrogateescape")).hexdigest()[:12]
