"""Job files: what to mesh, how finely, with which packer and mesher, where to write.

A job is YAML (or a dict) with the keys of :data:`JOB_SCHEMA`; see
``docs/job.md``. Unknown keys and wrong types are errors naming file:line and
the allowed keys. Paths in a job file are relative to the job file.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from .errors import JobError
from .knowledge import load_placements
from .meshing import mesher_names
from .packing import packer_names
from .schema import BOOLEAN, INTEGER, LIST, MAPPING, NUMBER, STRING, Field, in_range, non_negative, positive, validate
from .shapes import SHAPES
from .yamlfile import Located, load_yaml, located

OUTPUT_FORMATS = ("vtu", "msh", "inp", "bdf", "med")
ELEMENTS = ("tetrahedra", "hex-dominant")
HEX_DOMINANT_FORMATS = ("vtu", "msh", "inp")  # the writers that take hexahedra, prisms and pyramids


def _plain_name(value):
    if not value or value.startswith(".") or any(c in value for c in "/\\:"):
        return f"must be a plain file name without folders, got '{value}'"
    return None


def _formats_ok(value):
    unknown = [v for v in value if v not in OUTPUT_FORMATS]
    if unknown or not value:
        return f"has unknown or no formats {unknown}; allowed: {', '.join(OUTPUT_FORMATS)}"
    return None


def job_schema() -> dict:
    return {
        "geometry": Field(
            MAPPING,
            required=True,
            doc="what to mesh: 'shape' (+ 'parameters') or 'file'",
            fields={
                "shape": Field(STRING, choices=tuple(SHAPES), doc="a built-in parametric solid"),
                "parameters": Field(MAPPING, default={}, open_keys=True, doc="the shape's parameters"),
                "file": Field(
                    STRING,
                    doc="an STL, OBJ, PLY, OFF or GLB surface or a STEP, IGES or BREP model, relative to the job file",
                ),
                "allow_multiple_solids": Field(BOOLEAN, default=False, doc="accept several disconnected solids"),
                "feature_angle": Field(
                    NUMBER,
                    default=30.0,
                    check=in_range(0.0, 180.0),
                    doc="dihedral angle in degrees above which an edge is a feature edge",
                ),
            },
        ),
        "size": Field(NUMBER, check=positive, doc="global element size H, in model units (default: model size / 40)"),
        "min_size": Field(NUMBER, check=positive, doc="no element size below this"),
        "max_size": Field(NUMBER, check=positive, doc="no element size above this"),
        "recipe": Field(STRING, doc="a curated recipe (fuzzymesh recipes list)"),
        "place": Field(LIST, default=[], doc="pattern placements (see docs/rules.md)"),
        "knowledge": Field(
            LIST,
            default=[],
            items=Field(STRING),
            doc="extra rule/pattern/recipe files or folders, relative to the job file",
        ),
        "packer": Field(STRING, default="bubble", choices=tuple(packer_names()), doc="node placement method"),
        "mesher": Field(STRING, default="delaunay", choices=tuple(mesher_names()), doc="connection method"),
        "seed": Field(
            INTEGER, default=0, check=non_negative, doc="random seed >= 0; same input and seed give the same mesh"
        ),
        "output": Field(
            MAPPING,
            default=None,
            doc="where and what to write",
            fields={
                "directory": Field(STRING, default="out", doc="output folder, relative to the job file"),
                "name": Field(STRING, default="mesh", check=_plain_name, doc="base name of the mesh files"),
                "formats": Field(
                    LIST,
                    default=["vtu", "msh"],
                    items=Field(STRING),
                    check=_formats_ok,
                    doc=f"any of {', '.join(OUTPUT_FORMATS)}",
                ),
                "order": Field(
                    INTEGER,
                    default=1,
                    choices=(1, 2),
                    doc="element order: 1 (4-node tets) or 2 (10-node tets, boundary on the surface)",
                ),
                "elements": Field(
                    STRING,
                    default="tetrahedra",
                    choices=ELEMENTS,
                    doc="tetrahedra, or hex-dominant (hexahedra, prisms and pyramids recombined from the tets)",
                ),
            },
        ),
    }


@dataclass(frozen=True, kw_only=True)
class Job:
    """A validated job: a frozen value built by :func:`job_from_dict`; a changed one (the CLI's overrides) is a
    ``dataclasses.replace`` copy."""

    source: str  # job file path or '<dict>'
    base_dir: Path  # relative paths resolve against this
    shape: str | None
    shape_parameters: dict
    geometry_file: Path | None
    allow_multiple_solids: bool
    feature_angle: float
    size: float | None
    min_size: float | None
    max_size: float | None
    recipe: str | None
    placements: list
    knowledge: list[Path]
    packer: str
    mesher: str
    seed: int
    output_dir: Path
    output_name: str
    output_formats: list[str]
    raw: dict
    output_order: int = 1
    output_elements: str = "tetrahedra"

    def where(self, *keys) -> str:
        """file:line:col of a key path in the job file (as deep as it exists)."""
        node, where = self.raw, getattr(self.raw, "where", lambda key=None: self.source)()
        for key in keys:
            if not isinstance(node, Located) or key not in node:
                break
            where, node = node.where(key), node[key]
        return where


def load_job(path: str | Path) -> Job:
    """Read and validate a job file."""
    path = Path(path)
    data = load_yaml(path, JobError)
    return job_from_dict(data, base_dir=path.parent, source=str(path))


def job_from_dict(data, base_dir: str | Path = ".", source: str = "<dict>") -> Job:
    """Validate a job given as a (possibly located) mapping."""
    data = located(data, source)
    if not isinstance(data, Located):
        raise JobError("a job must be a YAML mapping", where=source, fix="see docs/job.md for the keys")
    values = validate(data, job_schema(), JobError)
    geo, geo_raw = values["geometry"], data["geometry"]
    if (geo["shape"] is None) == (geo["file"] is None):
        raise JobError(
            "'geometry' needs exactly one of 'shape' or 'file'",
            where=geo_raw.where(),
            fix=f"e.g. 'shape: plate_cylinder_junction' (shapes: {', '.join(SHAPES)})",
        )
    parameters = {}
    if geo["shape"] is not None:
        schema = SHAPES.details(geo["shape"])["parameters"]
        raw_params = geo_raw.get("parameters") or Located()
        if not isinstance(raw_params, Located):
            raw_params = located(raw_params, source)
        parameters = validate(raw_params, schema, JobError, f"geometry.parameters ({geo['shape']})")
    elif geo["parameters"]:
        raise JobError(
            "'parameters' is for built-in shapes only",
            where=geo_raw.where("parameters"),
            fix="remove it, or use 'shape:' instead of 'file:'",
        )
    if values["min_size"] and values["max_size"] and values["min_size"] > values["max_size"]:
        raise JobError("'min_size' is larger than 'max_size'", where=data.where("min_size"), fix="swap or fix them")
    output = values["output"] or validate(Located(), job_schema()["output"].fields, JobError, "output")
    if output["elements"] == "hex-dominant":
        other = [f for f in output["formats"] if f not in HEX_DOMINANT_FORMATS]
        if other or output["order"] != 1:
            raise JobError(
                "hex-dominant elements are written as linear cells in "
                f"{', '.join(HEX_DOMINANT_FORMATS)} only" + (f", not {', '.join(other)}" if other else ", order 1"),
                where=data.where("output"),
                fix=f"use formats from {', '.join(HEX_DOMINANT_FORMATS)} and order 1, or elements: tetrahedra",
            )
    packer = values["packer"]
    if output["elements"] == "hex-dominant" and "packer" not in data:
        packer = "grid"  # nodes on a grid aligned with the solid's frame (engine/packing/grid.py)
    mesher = values["mesher"]
    if output["elements"] == "hex-dominant" and "mesher" not in data:
        mesher = "hex-core"  # the grid's boxes kept as hexahedra (engine/meshing/hexcore.py)
    base_dir = Path(base_dir)
    return Job(
        source=source,
        base_dir=base_dir,
        shape=geo["shape"],
        shape_parameters=parameters,
        geometry_file=(base_dir / geo["file"]) if geo["file"] else None,
        allow_multiple_solids=geo["allow_multiple_solids"],
        feature_angle=float(geo["feature_angle"]),
        size=values["size"],
        min_size=values["min_size"],
        max_size=values["max_size"],
        recipe=values["recipe"],
        placements=load_placements(data["place"], data.where("place"), "job", "job/place") if "place" in data else [],
        knowledge=[base_dir / k for k in values["knowledge"]],
        packer=packer,
        mesher=mesher,
        seed=values["seed"],
        output_dir=base_dir / output["directory"],
        output_name=output["name"],
        output_formats=list(dict.fromkeys(output["formats"])),
        raw=data,
        output_order=output["order"],
        output_elements=output["elements"],
    )


def default_job() -> Job:
    """The built-in example, the paper's Fig. 10 (b): the plate-cylinder junction with the cylinder near the plate
    edge, sized by the recipe junction-edge at H = 12 (about 91,000 tetrahedra in about seven seconds)."""
    return job_from_dict(
        {"geometry": {"shape": "plate_cylinder_junction"}, "recipe": "junction-edge", "size": 12.0},
        base_dir=Path.cwd(),
        source="<default example>",
    )


__all__ = ["Job", "load_job", "job_from_dict", "default_job", "OUTPUT_FORMATS"]
