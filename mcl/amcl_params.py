"""ROS AMCL parameters as an mcl config: ``mcl config from-amcl PARAMS``.

Reads the parameters of a ROS 1 ``amcl`` node (a rosparam YAML, flat or under the node's name, or a ``.launch`` file
with ``<node pkg="amcl">``) or of a ROS 2 ``nav2_amcl`` node (a nav2 params file, ``amcl: ros__parameters: ...``
among the other nodes, or the bare ``ros__parameters`` mapping) and writes the mcl config keys they correspond to,
each commented with the AMCL parameter it came from. Only those keys are written: an mcl config needs only the keys
it changes (mcl.config), so the output runs as it is (``mcl run out.yaml --bag B``) or merges into a config.

The mapping follows AMCL's sources, not its documentation alone (ros-planning/navigation ``amcl/src/amcl_node.cpp``,
``amcl/src/amcl/sensors/amcl_odom.cpp``, ``amcl_laser.cpp``, ``amcl/src/amcl/pf/pf.c``; ros-navigation/navigation2
``nav2_amcl/src/amcl_node.cpp``, ``motion_model/differential_motion_model.cpp``,
``sensors/laser/likelihood_field_model_prob.cpp``):

- Odometry alphas. ROS 1 ``diff-corrected`` and nav2's DifferentialMotionModel draw each noise with the standard
  deviation ``sqrt(alpha1 rot^2 + alpha2 trans^2)``: the book's variance form, mcl's ``motion.noise_form:
  variance``, alpha for alpha. ROS 1's ``diff`` (its default) passes ``alpha1 rot^2 + alpha2 trans^2`` itself as the
  standard deviation (ros-planning/navigation#20): no mcl form has that; the alphas are kept and a warning says how
  much wider mcl's noise is then. The ``omni`` models are mcl's ``motion.model: omni``, their alpha1 and alpha4 swapped
  into mcl's roles and ``alpha5`` its ``motion.alpha_strafe`` (ROS 1's uncorrected ``omni`` has ``diff``'s bug: a
  warning).
- KLD sampling: AMCL's ``kld_z``/``pf_z`` is the normal quantile z itself in ``pf_resample_limit``, so mcl's
  ``kld_delta`` = 1 - Phi(z) (the 0.99 default: delta = 0.161); ``kld_err``/``pf_err`` is ``kld_epsilon``.
- Range finder weights. AMCL's Gaussian is unnormalised (``z_hit * exp(-d^2 / 2 sigma^2)``), mcl's (the book's) is
  a density: ``z_hit * sqrt(2 pi) sigma_hit`` gives the same p(z) up to one factor common to every particle, which
  changes no weight, so the weights are then scaled to sum to 1 (mcl's beam model requires it).
- ``recovery_alpha_slow``/``fast`` both above 0 are AMCL's augmented MCL (``pf.c``: w_diff = 1 - w_fast / w_slow):
  ``filter.recovery: augmented``; both 0 is no recovery in AMCL, and mcl's own default is kept (a note says that
  ``filter.recovery: false`` is AMCL's).

:func:`convert` returns the YAML text and the warnings; it loads the text with :func:`mcl.config.load_config`
first, so a value mcl refuses is an error naming the AMCL parameter it came from.
"""

from __future__ import annotations

import ast
import difflib
import math
import operator
import re
import tempfile
import textwrap
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from mcl.errors import ConfigError, MclError
from mcl.yamlfile import _Loader, finite_number, parse, short_repr

WIDTH = 118  # the output's lines, comments wrapped
ROS1 = "ROS 1 amcl"
NAV2 = "nav2_amcl"


@dataclass(frozen=True)
class _Param:
    key: str  # the name used below (nav2's where it has one)
    ros1: str | None  # the ROS 1 amcl name (None: not a ROS 1 parameter)
    nav2: str | None  # the nav2_amcl name
    kind: type  # float, int, bool or str
    d1: Any = None  # ROS 1 amcl_node.cpp's default
    d2: Any = None  # nav2_amcl amcl_node.cpp's default


def _both(key, kind, d1, d2=None):
    return _Param(key, key, key, kind, d1, d1 if d2 is None else d2)


PARAMS = (
    *(_Param(f"alpha{i}", f"odom_alpha{i}", f"alpha{i}", float, 0.2, 0.2) for i in range(1, 6)),
    _Param("robot_model_type", "odom_model_type", "robot_model_type", str, "diff", "nav2_amcl::DifferentialMotionModel"),
    _Param("z_hit", "laser_z_hit", "z_hit", float, 0.95, 0.5),
    _Param("z_short", "laser_z_short", "z_short", float, 0.1, 0.05),
    _Param("z_max", "laser_z_max", "z_max", float, 0.05, 0.05),
    _Param("z_rand", "laser_z_rand", "z_rand", float, 0.05, 0.5),
    _Param("sigma_hit", "laser_sigma_hit", "sigma_hit", float, 0.2, 0.2),
    _Param("lambda_short", "laser_lambda_short", "lambda_short", float, 0.1, 0.1),
    _both("laser_likelihood_max_dist", float, 2.0),
    _both("laser_model_type", str, "likelihood_field"),
    _Param("max_beams", "laser_max_beams", "max_beams", int, 30, 60),
    _both("laser_min_range", float, -1.0),
    _both("laser_max_range", float, -1.0, 100.0),
    _both("min_particles", int, 100, 500),
    _both("max_particles", int, 5000, 2000),
    _Param("pf_err", "kld_err", "pf_err", float, 0.01, 0.05),
    _Param("pf_z", "kld_z", "pf_z", float, 0.99, 0.99),
    _both("update_min_d", float, 0.2, 0.25),
    _both("update_min_a", float, math.pi / 6, 0.2),
    _both("resample_interval", int, 2, 1),
    _Param("selective_resampling", "selective_resampling", None, bool, False),  # ROS 1 amcl 1.14.6 on
    # ROS 1: amcl_node.cpp reads 0.001 and 0.1 when the parameter is absent (its wiki page and AMCL.cfg say 0)
    _both("recovery_alpha_slow", float, 0.001, 0.0),
    _both("recovery_alpha_fast", float, 0.1, 0.0),
    _both("do_beamskip", bool, False),
    _both("beam_skip_distance", float, 0.5),
    _both("beam_skip_threshold", float, 0.3),
    _both("beam_skip_error_threshold", float, 0.9),
    _both("odom_frame_id", str, "odom"),
    _both("base_frame_id", str, "base_link", "base_footprint"),
    _both("global_frame_id", str, "map"),
    _Param("initial_pose.x", "initial_pose_x", "initial_pose.x", float, 0.0, 0.0),
    _Param("initial_pose.y", "initial_pose_y", "initial_pose.y", float, 0.0, 0.0),
    _Param("initial_pose.yaw", "initial_pose_a", "initial_pose.yaw", float, 0.0, 0.0),
    _Param("initial_pose.z", None, "initial_pose.z", float, None, 0.0),
    _Param("initial_cov_xx", "initial_cov_xx", None, float, 0.25),
    _Param("initial_cov_yy", "initial_cov_yy", None, float, 0.25),
    _Param("initial_cov_aa", "initial_cov_aa", None, float, (math.pi / 12) ** 2),
    _Param("set_initial_pose", None, "set_initial_pose", bool, None, False),
    _Param("scan_topic", None, "scan_topic", str, None, "scan"),
    _Param("map_topic", None, "map_topic", str, None, "map"),
    # no mcl counterpart: listed as not used
    _both("transform_tolerance", float, 0.1, 1.0),
    _both("save_pose_rate", float, 0.5),
    _both("tf_broadcast", bool, True),
    _both("first_map_only", bool, False),
    _Param("always_reset_initial_pose", None, "always_reset_initial_pose", bool),
    _Param("gui_publish_rate", "gui_publish_rate", None, float),
    _Param("use_map_topic", "use_map_topic", None, bool),
    _Param("bag_scan_period", "bag_scan_period", None, float),
    _Param("restore_defaults", "restore_defaults", None, bool),
    _Param("force_update_after_initialpose", "force_update_after_initialpose", None, bool),
    _Param("force_update_after_set_map", "force_update_after_set_map", None, bool),
    _Param("std_warn_level_x", "std_warn_level_x", None, float),
    _Param("std_warn_level_y", "std_warn_level_y", None, float),
    _Param("std_warn_level_yaw", "std_warn_level_yaw", None, float),
    _Param("initialize_at_saved_pose", None, "initialize_at_saved_pose", bool),
    _Param("saved_pose_filepath", None, "saved_pose_filepath", str),
    _Param("freespace_downsampling", None, "freespace_downsampling", int),
    _Param("random_seed", None, "random_seed", int, None, -1),
)
UNUSED = {"transform_tolerance": "the map -> odom transform's post-dating", "save_pose_rate": "",
          "tf_broadcast": "", "first_map_only": "", "always_reset_initial_pose": "", "gui_publish_rate": "",
          "use_map_topic": "mcl reads a map file, else the bag's topics.map", "bag_scan_period": "",
          "restore_defaults": "", "force_update_after_initialpose": "", "force_update_after_set_map": "",
          "global_frame_id": "mcl's estimate is in the map's frame",
          "initial_pose.z": "", "std_warn_level_x": "mcl's quality signal says when the track is in doubt",
          "std_warn_level_y": "", "std_warn_level_yaw": "", "initialize_at_saved_pose": "", "saved_pose_filepath": "",
          "freespace_downsampling": "mcl draws global poses from every free cell"}
# ROS 1 reads this misspelling too (amcl_node.cpp; navigation#790)
ALIASES = {"beam_skip_error_threshold_": "beam_skip_error_threshold"}
# parameters every ROS 2 node has, and rosparam's own
GENERIC = ("use_sim_time", "qos_overrides", "introspection_mode", "bond_heartbeat_period", "start_type_description_service",
           "allow_parameter_qos_overrides")

_BY_NAME = {flavour: {getattr(p, attr): p for p in PARAMS if getattr(p, attr)} for flavour, attr in
            ((ROS1, "ros1"), (NAV2, "nav2"))}
_BY_KEY = {p.key: p for p in PARAMS}


# ----------------------------------------------------------------------------- reading the parameters


@dataclass
class Source:
    """The AMCL parameters found in a file: ``params`` by their names there, flat (nav2's nested ``initial_pose:
    {x: ...}`` as ``initial_pose.x``), ``flavour`` ROS1 or NAV2, ``where`` what held them, ``remaps`` a launch
    node's topic remappings (from -> to, each ``to`` resolved: absolute, or in ``ns``), ``ns`` the launch node's
    namespace ("" for the root; its ``<group ns=>`` and ``<node ns=>``), ``warnings`` what could not be read."""

    path: Path
    flavour: str
    params: dict
    where: str
    remaps: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)
    ns: str = ""
    unresolved: set = field(default_factory=set)  # names the file gives a value mcl could not resolve ($(eval))


def _flatten(d: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in d.items():
        name = f"{prefix}{k}"
        if isinstance(v, dict) and v:
            out.update(_flatten(v, name + "."))
        else:
            out[name] = v
    return out


# names other nodes have too (a controller's transform_tolerance, a costmap's frames): they alone make no AMCL node
_WEAK = {*UNUSED, "odom_frame_id", "base_frame_id", "scan_topic", "map_topic"}
_STRONG = {name for flavour in (ROS1, NAV2) for name, p in _BY_NAME[flavour].items() if p.key not in _WEAK}
# names no other localization node of a nav2 params file holds (z_hit, sigma_hit, laser_max_range are common)
_DISTINCT = {"laser_model_type", "robot_model_type", "pf_z", "pf_err", "recovery_alpha_slow",
             "recovery_alpha_fast", "max_particles", "min_particles", "odom_model_type", "kld_z", "kld_err"}
# the sections of an mcl config: such a file is not AMCL's
_MCL_SECTIONS = ("filter", "motion", "sensor", "quality", "rerun", "topics", "frames")


def _score(params: dict) -> int:
    """How many names only an AMCL node has (after ALIASES) the mapping holds."""
    return sum(ALIASES.get(str(k), str(k)) in _STRONG for k in _flatten(params))


def _flavour_of(params: dict) -> tuple[str, bool]:
    """ROS1 or NAV2 by the names only one of them has (a tie: nav2, whose names are the plainer), and whether no
    such name decided it."""
    names = [ALIASES.get(str(k), str(k)) for k in _flatten(params)]
    ros1 = sum(n in _BY_NAME[ROS1] and n not in _BY_NAME[NAV2] for n in names)
    nav2 = sum(n in _BY_NAME[NAV2] and n not in _BY_NAME[ROS1] for n in names)
    return (ROS1 if ros1 > nav2 else NAV2), ros1 == nav2 == 0


def _walk(node: Any, path: tuple = (), depth: int = 0):
    """(path, mapping) of every mapping in a YAML document, to depth 5."""
    if not isinstance(node, dict) or depth > 5:
        return
    yield path, node
    for k, v in node.items():
        yield from _walk(v, (*path, str(k)), depth + 1)


def _node_namespace(path: tuple) -> str:
    """The namespace of a nav2 params file's node at ``path`` (``/robot1/amcl:`` or ``robot1: amcl:``: robot1), in
    which its relative topics resolve as ROS 2 resolves them; "" at the root or under a wildcard (``/**/amcl``)."""
    parts = [q for k in path for q in str(k).split("/") if q]
    return "" if any("*" in q for q in parts) else "/".join(parts[:-1])


def _is_amcl_name(path: tuple) -> bool:
    return bool(path) and path[-1].strip("/").split("/")[-1].endswith("amcl")


def _from_yaml(path: Path, doc: Any) -> Source:
    if isinstance(doc, dict) and sum(isinstance(doc.get(k), dict) for k in _MCL_SECTIONS) >= 1 and not any(
            isinstance(v, dict) and "ros__parameters" in v for v in doc.values()) and _score(doc) == 0:
        raise MclError(f"{path}: an mcl config (its sections: {', '.join(k for k in _MCL_SECTIONS if k in doc)}), "
                       "not AMCL parameters")
    nodes = [(p, m["ros__parameters"]) for p, m in _walk(doc) if isinstance(m.get("ros__parameters"), dict)]
    if nodes:  # a nav2 params file: the amcl node's block, else the one that holds AMCL's names
        named = [(p, m) for p, m in nodes if _is_amcl_name(p)]
        # a node not named amcl must hold a name only AMCL has: another localizer's z_hit and sigma_hit are not enough
        pick = named or sorted((n for n in nodes if _score(n[1]) and _DISTINCT & set(map(str, _flatten(n[1])))),
                               key=lambda n: -_score(n[1]))
        if pick:
            p, params = pick[0]
            src = Source(path, NAV2, _flatten(params), f"{'/'.join(p) + ': ' if p else ''}ros__parameters",
                         ns=_node_namespace(p))
            if len(named) > 1:
                src.warnings.append(f"{len(named)} amcl nodes ({', '.join('/'.join(n[0]) for n in named)}): "
                                    f"the first ({'/'.join(p)}) is read")
            return src
        listed = ", ".join("/".join(n[0]) or "(top)" for n in nodes[:6]) + (", ..." if len(nodes) > 6 else "")
        raise MclError(f"{path}: no AMCL parameters found: no amcl node among its nodes ({listed}); a nav2 params "
                       "file's are under amcl: ros__parameters:")
    candidates = [(p, m) for p, m in _walk(doc) if _score(m)]
    if not candidates:
        raise MclError(f"{path}: no AMCL parameters found (expected a nav2 params file with amcl: ros__parameters:, "
                       "ROS 1 amcl parameters, flat or under the node's name, or a .launch file with "
                       "<node pkg=\"amcl\">)")
    named = [c for c in candidates if _is_amcl_name(c[0])]
    p, params = named[0] if named else max(candidates, key=lambda c: _score(c[1]))
    flavour, guessed = _flavour_of(params)
    if guessed and p:  # under a node's name without ros__parameters: a rosparam file (nav2 never reads one so)
        flavour = ROS1
    src = Source(path, flavour, _flatten(params), "/".join(p) if p else "the top level")
    if guessed:
        why = (f"under {'/'.join(p)}: without ros__parameters: (a rosparam file) read as ROS 1 amcl's" if p else
               "read as nav2_amcl's")
        src.warnings.append(f"every name here is both ROS 1 amcl's and nav2_amcl's: {why} (its defaults fill a "
                            "group's missing parameters)")
    return src


_SUBST = re.compile(r"\$\((\w+)\s*([^)]*)\)")
_AMCL_PKGS = ("amcl", "nav2_amcl")


def _roslaunch_value(text: str, kind: str | None) -> Any:
    """A <param value=...> as roslaunch types it: the type attribute, else bool, int, float, or the string."""
    t = text.strip()
    if kind in ("str", "string"):
        return text
    if kind in (None, "auto", "bool", "boolean") and t.lower() in ("true", "false"):
        return t.lower() == "true"
    if kind in (None, "auto", "int"):
        try:
            return int(t)
        except ValueError:
            pass
    if kind in (None, "auto", "double", "float", "int"):
        try:
            return float(t)
        except ValueError:
            pass
    return text


def _from_launch(path: Path, text: str) -> Source:
    try:
        root = ET.fromstring(text)
    except ET.ParseError as e:
        line = getattr(e, "position", (None,))[0]
        raise MclError(f"{path}{f':{line}' if line else ''}: invalid XML: {str(e).split(':')[0]}") from None
    warnings: list[str] = []

    def subst(value: str, what: str, args: dict) -> str | None:
        """$(arg NAME) replaced from ``args``; None (and a warning) for any other substitution."""
        if value.strip().startswith("$(eval "):  # the whole value is one Python expression (roslaunch's rule)
            warnings.append(f"{what}: {value.strip()} cannot be resolved here (roslaunch's $(eval) is not "
                            "evaluated): not used")
            return None

        def one(m):
            if m.group(1) == "arg" and m.group(2).strip() in args:
                return args[m.group(2).strip()]
            if m.group(1) == "find":  # the package's folder: the launch file's ancestor of that name
                pkg = next((p for p in path.resolve().parents if p.name == m.group(2).strip()), None)
                if pkg is not None:
                    return str(pkg)
            raise KeyError(m.group(0))

        for _ in range(5):  # an arg's default may name another arg
            try:
                new = _SUBST.sub(one, value)
            except KeyError as e:
                warnings.append(f"{what}: {e.args[0]} cannot be resolved here: not used")
                return None
            if new == value:
                return new
            value = new
        return value

    def skipped(el, args: dict) -> bool:
        """roslaunch's if= / unless= on an element (true/false/1/0 once substituted): True when it is not loaded; an
        unresolved condition is loaded, with subst's warning."""
        for attr, load_when in (("if", True), ("unless", False)):
            cond = el.get(attr)
            if cond is not None:
                value = subst(cond, f"<{el.tag} {attr}=>", args)
                if value is not None and value.strip().lower() in ("true", "1", "false", "0"):
                    if (value.strip().lower() in ("true", "1")) != load_when:
                        return True
        return False

    # As roslaunch reads the file: in document order, each <arg> declared where it stands (one in a <group> for that
    # group only), and an <arg>, <group> or <node> whose if= / unless= is false skipped with all it holds (nested
    # groups too): an amcl node in a group whose condition is false is not launched. Only the conditions that can
    # matter are evaluated (another node's, or a group's without an amcl node, would only add warnings).
    nodes: list[tuple] = []  # (amcl node launched, the args, the remaps and the namespace in scope there)
    scoped: list[tuple] = []  # (<param> or <rosparam> outside a node, the args and the namespace there)
    not_launched = 0

    def remap_of(el, args: dict, ns: str) -> tuple[str, str] | None:
        """A <remap> of the scan or map topic as (from, to resolved in ``ns``), else None."""
        frm = el.get("from", "")
        if frm.strip("/") not in ("scan", "map") or not el.get("to"):
            return None
        to = subst(el.get("to"), "<remap>", args)
        return None if to is None else (frm.strip("/"), _resolve(to, ns))

    def inner(el, args: dict, ns: str) -> str:
        """The namespace inside ``el`` (a <group ns=> or <node ns=>, resolved in ``ns``)."""
        raw = el.get("ns")
        value = None if raw is None else subst(raw, f"<{el.tag} ns=>", args)
        return ns if value is None else _resolve(value, ns)

    def walk(parent, args: dict, remaps: dict, ns: str) -> None:
        nonlocal not_launched
        for el in parent:
            if el.tag == "remap":  # roslaunch: applies to the nodes after it in its scope (the file, a group)
                r = None if skipped(el, args) else remap_of(el, args, ns)
                if r is not None:
                    remaps[r[0]] = r[1]
                continue
            if el.tag in ("param", "rosparam"):  # the scope's own: read when they name the amcl node's parameters
                if not skipped(el, args):
                    scoped.append((el, dict(args), ns))
                continue
            if el.tag not in ("arg", "group", "node"):
                continue
            if el.tag != "arg" and not any(n.get("pkg") in _AMCL_PKGS for n in el.iter("node")):
                # a group with no amcl node may still set its parameters (<group ns="amcl"><param .../>)
                if el.tag == "group" and any(x.tag in ("param", "rosparam") for x in el.iter()) and not skipped(el, args):
                    walk(el, dict(args), {}, inner(el, args, ns))
                continue
            if skipped(el, args):
                not_launched += sum(n.get("pkg") in _AMCL_PKGS for n in el.iter("node"))
            elif el.tag == "arg" and el.get("name") is not None:
                value = el.get("value", el.get("default"))
                if value is not None:
                    args.setdefault(el.get("name"), value)
            elif el.tag == "group":
                walk(el, dict(args), dict(remaps), inner(el, args, ns))
            elif el.tag == "node" and el.get("pkg") in _AMCL_PKGS:
                nodes.append((el, dict(args), dict(remaps), inner(el, args, ns)))

    walk(root, {}, {}, "")
    if not nodes:
        includes = [i.get("file", "") for i in root.iter("include")]
        extra = (f"; it includes {', '.join(includes)}: give the included file" if includes else "")
        if not_launched:
            raise MclError(f"{path}: no <node pkg=\"amcl\"> is launched with the args' defaults: {not_launched} amcl "
                           f"node{'s' if not_launched > 1 else ''} under an if= / unless= that is false (on the node or "
                           f"a <group> around it){extra}")
        raise MclError(f"{path}: no <node pkg=\"amcl\"> in this launch file{extra}")
    node, args, remaps, ns = nodes[0]
    if len(nodes) > 1:
        warnings.append(f"{len(nodes)} amcl nodes launched: the first ({node.get('name', 'amcl')}) is read")
    flavour = ROS1 if node.get("pkg") == "amcl" else NAV2
    params: dict = {}
    unresolved: set = set()

    def absolute(name: str, ns: str) -> str:
        return "/" + "/".join(q for q in (*([] if name.startswith("/") else ns.split("/")), *name.split("/")) if q)

    def rosparam(el, args: dict) -> dict | None:
        """A <rosparam command="load"> (file= or its text; param= puts it under a name) as flat names."""
        loaded = None
        if el.get("file"):
            file = subst(el.get("file"), "<rosparam file>", args)
            if file is not None:
                f = Path(file)
                f = f if f.is_absolute() else path.parent / f
                loaded = _load_rosparam(_read_text(f), str(f), warnings)
        elif (el.text or "").strip():
            body = el.text if el.get("subst_value") not in ("true", "True") else subst(el.text, "<rosparam>", args)
            try:
                loaded = _load_rosparam(body, "a <rosparam> block", warnings) if body is not None else None
            except MclError as e:
                warnings.append(f"{e}: not read")
        if el.get("param") and loaded is not None:
            loaded = {el.get("param"): loaded}
        return _flatten(loaded) if isinstance(loaded, dict) else None

    def param(el, args: dict, name: str) -> None:
        if el.get("value") is None:
            warnings.append(f"{name}: a <param> without value= (command=, textfile=) is not read")
            return
        value = subst(el.get("value"), name, args)
        if value is not None:
            params[name] = _roslaunch_value(value, el.get("type"))
        else:
            unresolved.add(name)

    # roslaunch sets the parameters of the whole file before it starts a node, the later of two in document order
    # winning: those outside the node that name its own (<param name="amcl/x">, <rosparam ns="amcl">) count as its
    # own, in their place among the node's
    private = absolute(node.get("name", "amcl"), ns)
    order = {el: i for i, el in enumerate(root.iter())}

    def under_private(where: str):
        """The flat-name prefix of the node's parameters inside a rosparam loaded at namespace ``where``, or None
        when the node's private namespace is not inside it."""
        base = where.rstrip("/")
        if private == base:
            return ""
        if not private.startswith(base + "/"):
            return None
        inside = private[len(base):].strip("/")
        return inside.replace("/", ".") + "."

    def load_under(el, el_args, where: str) -> None:
        prefix = under_private(where)
        if prefix is None:
            return
        flat = rosparam(el, el_args) or {}
        params.update({k[len(prefix):]: v for k, v in flat.items() if k.startswith(prefix)})

    todo = [(order.get(el, -1), el, el_args, el_ns, False) for el, el_args, el_ns in scoped]
    todo += [(order.get(el, -1), el, args, ns, True) for el in node]
    for _, el, el_args, el_ns, own in sorted(todo, key=lambda t: t[0]):
        if own and skipped(el, el_args):
            continue
        if el.tag == "param" and not own and el.get("name"):
            full = absolute(el.get("name"), el_ns)
            if full.startswith(private + "/"):
                param(el, el_args, full[len(private) + 1:])
        elif el.tag == "rosparam" and not own and el.get("command", "load") == "load":
            load_under(el, el_args, absolute(el.get("ns") or "", el_ns))
        elif el.tag == "param" and el.get("from") is not None and not el.get("name"):
            warnings.append(f"<param from=\"{el.get('from')}\"> (a ROS 2 parameter file) is not read: give that "
                            "file to mcl config from-amcl")
        elif el.tag == "param" and el.get("name"):
            name = el.get("name")
            if name.startswith("/"):  # an absolute name: the node's own only if under its private namespace
                full = absolute(name, "")
                if full.startswith(private + "/"):
                    param(el, el_args, full[len(private) + 1:])
            else:
                param(el, el_args, name.lstrip("~"))
        elif el.tag == "rosparam" and el.get("command", "load") == "load":
            ns_attr = (el.get("ns") or "").strip()
            if ns_attr.startswith("/"):  # absolute: read where it names the node's private namespace
                load_under(el, el_args, absolute(ns_attr, ""))
            elif ns_attr.strip("/~"):  # under the node's own namespace: ~ns/..., names AMCL never reads
                warnings.append(f"<rosparam ns=\"{ns_attr}\"> in the node: its parameters are under "
                                f"~{ns_attr.strip('/~')}/, where AMCL does not read them: not read")
            else:
                params.update(rosparam(el, el_args) or {})
    for el in node:
        if skipped(el, args):
            continue
        if el.tag == "remap":  # the node's own: over its scope's
            r = remap_of(el, args, ns)
            if r is not None:
                remaps[r[0]] = r[1]
    return Source(path, flavour, params, f"<node name=\"{node.get('name', 'amcl')}\">", remaps, warnings,
                  ns.strip("/"), unresolved)


def _resolve(name: str, ns: str) -> str:
    """A ROS name resolved in namespace ``ns`` (roslaunch's: absolute names stay, relative ones go under ``ns``;
    ``~private`` names are not topics here and are left as they are)."""
    name = name.strip()
    if name.startswith("/") or name.startswith("~") or not ns.strip("/"):
        return name
    return "/" + "/".join(p for p in (*ns.strip("/").split("/"), name) if p)


class _Rosparam(_Loader):
    """mcl's loader (``mcl.yamlfile``: its numbers) as rosparam (PyYAML) reads a parameter file: the last of a key
    given twice in one mapping is kept, and recorded (line, key) in ``duplicates`` (PAL's amcl.yaml repeats
    laser_lambda_short, which mcl's own files refuse); rosparam's angle tags are read (ros_comm
    ``rosparam/__init__.py``): ``!degrees 30`` and ``deg(30)`` are 30 degrees in radians, ``!radians pi/6`` and
    ``rad(pi/6)`` an expression of numbers and pi."""

    def __init__(self, stream):
        super().__init__(stream)
        self.duplicates: list = []

    def duplicate(self, key, mark) -> None:
        self.duplicates.append((mark.line + 1, key))


_ARITH = {ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul, ast.Div: operator.truediv}


def _radian_expression(text: str) -> float:
    """rosparam's ``!radians`` value: numbers and ``pi`` under + - * / and brackets (rosparam evaluates it as
    Python; nothing else is read here)."""

    def value(n):
        if isinstance(n, ast.Constant) and type(n.value) in (int, float):
            return float(n.value)
        if isinstance(n, ast.Name) and n.id == "pi" or (isinstance(n, ast.Attribute) and n.attr == "pi"
                                                       and isinstance(n.value, ast.Name) and n.value.id == "math"):
            return math.pi
        if isinstance(n, ast.UnaryOp) and isinstance(n.op, (ast.UAdd, ast.USub)):
            return value(n.operand) * (-1.0 if isinstance(n.op, ast.USub) else 1.0)
        if isinstance(n, ast.BinOp) and type(n.op) in _ARITH:
            return _ARITH[type(n.op)](value(n.left), value(n.right))
        raise ValueError(text)

    return value(ast.parse(text.strip(), mode="eval").body)


def _angle(loader, node, degrees: bool) -> float:
    text = str(loader.construct_scalar(node)).strip()
    prefix = "deg(" if degrees else "rad("
    expr = text[4:-1] if text.startswith(prefix) and text.endswith(")") else text
    try:
        v = math.radians(float(expr)) if degrees else _radian_expression(expr)
    except (ValueError, SyntaxError, TypeError, ZeroDivisionError, OverflowError, RecursionError, MemoryError):
        what = "a number of degrees" if degrees else "a radian expression (numbers and pi)"
        raise yaml.constructor.ConstructorError(None, None, f"{short_repr(text)} is not {what}",
                                                node.start_mark) from None
    if not math.isfinite(v):
        raise yaml.constructor.ConstructorError(None, None, f"{short_repr(text)} is not finite", node.start_mark)
    return v


_Rosparam.add_constructor("!degrees", lambda loader, node: _angle(loader, node, True))
_Rosparam.add_constructor("!radians", lambda loader, node: _angle(loader, node, False))
_Rosparam.add_implicit_resolver("!degrees", re.compile(r"^deg\([^)]*\)$"), ["d"])
_Rosparam.add_implicit_resolver("!radians", re.compile(r"^rad\([^)]*\)$"), ["r"])


def _load_rosparam(text: str, name: str, warnings: list, where: str | None = None) -> Any:
    """The YAML document ``text`` (of file ``name``) read as rosparam reads it (``_Rosparam``); a key given twice is
    a warning in ``warnings`` (its line after ``where``, default ``name:``), invalid YAML an MclError of one line
    naming ``name`` and the line."""
    loader = _Rosparam(text)
    doc = parse(loader, name, MclError)
    for line, key in loader.duplicates:
        warnings.append(f"{f'{name}:' if where is None else where}{line}: {key} given twice: the last is read, as "
                        "rosparam does")
    return doc


def _read_text(path: Path) -> str:
    try:
        return path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise MclError(f"{path}: not a text file (expected AMCL parameters as YAML or a .launch file)") from None
    except (OSError, ValueError) as e:
        raise MclError(f"{path}: cannot read: {getattr(e, 'strerror', None) or type(e).__name__}") from None


def read_source(path: str | Path) -> Source:
    """The AMCL parameters of ``path``: a .launch / .xml file (or any file starting with '<') read as roslaunch
    XML, anything else as YAML. MclError (one line naming the file) when it is neither or holds none."""
    path = Path(path)
    text = _read_text(path)
    if path.suffix.lower() in (".launch", ".xml") or text.lstrip().startswith("<"):
        return _from_launch(path, text)
    dup: list = []
    doc = _load_rosparam(text, str(path), dup, "line ")  # read_source's caller names the file
    src = _from_yaml(path, doc)
    src.warnings[:0] = dup
    return src


# ----------------------------------------------------------------------------- the mcl keys


def _fmt(v: Any) -> str:
    """A value as YAML that mcl reads back the same (floats to 6 significant digits)."""
    if isinstance(v, float):
        v = float(f"{v:.6g}")
    elif isinstance(v, (list, tuple)):
        v = [float(f"{x:.6g}") if isinstance(x, float) else x for x in v]
    text = yaml.safe_dump(v, default_flow_style=True, width=10_000)
    return text.removesuffix("\n").removesuffix("\n...").strip()


def _num(v: Any) -> str:
    """An AMCL value in a comment: as short as it reads."""
    if isinstance(v, float):
        return f"{v:g}"
    if isinstance(v, bool):
        return str(v).lower()
    return str(v)


@dataclass
class _Entry:
    key: str  # dotted mcl key
    value: Any
    comment: str
    sources: tuple  # (AMCL name, value) pairs it came from


class _Converter:
    def __init__(self, src: Source):
        self.src = src
        self.flavour = src.flavour
        self.values: dict = {}  # key -> value read from the file
        self.names: dict = {}  # key -> the name the file gave it
        self.entries: list[_Entry] = []
        self.notes: list[str] = []
        self.unused: list[str] = []
        self.warnings: list[str] = list(src.warnings)
        self.used: set = set()

    # -- reading

    def name(self, key: str) -> str:
        p = _BY_KEY[key]
        return self.names.get(key) or (p.ros1 if self.flavour == ROS1 else p.nav2) or p.key

    def given(self, key: str) -> bool:
        return key in self.values

    def get(self, key: str) -> Any:
        """The file's value, else AMCL's default in this flavour."""
        if key in self.values:
            return self.values[key]
        p = _BY_KEY[key]
        return p.d1 if self.flavour == ROS1 else p.d2

    def said(self, key: str) -> str:
        """'name value' for a comment, '(AMCL's default)' when the file does not give it."""
        extra = ("" if self.given(key) else
                 " (AMCL's default: the file's value could not be resolved)" if self.name(key) in self.src.unresolved
                 else " (AMCL's default)")
        return f"{self.name(key)} {_num(self.get(key))}{extra}"

    def read(self) -> None:
        other = NAV2 if self.flavour == ROS1 else ROS1
        for raw_name, raw in self.src.params.items():
            name = ALIASES.get(str(raw_name), str(raw_name)) if self.flavour == ROS1 else str(raw_name)
            p = _BY_NAME[self.flavour].get(name)
            if p is None:
                q = _BY_NAME[other].get(name)
                if q is not None:
                    right = getattr(q, "ros1" if self.flavour == ROS1 else "nav2")
                    instead = f" ({self.flavour} reads {right})" if right else ""
                    self.warnings.append(f"{raw_name}: a {other} parameter, not a {self.flavour} one{instead}: "
                                         "not used")
                elif str(raw_name).split(".")[0] in GENERIC:
                    self.unused.append(f"{raw_name} {_num(raw)}")
                else:
                    hint = difflib.get_close_matches(name, list(_BY_NAME[self.flavour]), n=1, cutoff=0.6)
                    extra = f" (did you mean {hint[0]}?)" if hint else ""
                    self.warnings.append(f"{raw_name}: not a {self.flavour} parameter{extra}: not used")
                continue
            if p.key in self.values:  # beam_skip_error_threshold and its misspelling: ROS 1 reads the misspelt one
                keep = self.names[p.key] if self.names[p.key] in ALIASES else str(raw_name)
                self.warnings.append(f"{raw_name}: given as {self.names[p.key]} too: {keep} is read, as AMCL does")
                if keep != str(raw_name):
                    continue
            self.values[p.key] = self._coerce(raw, p, str(raw_name))
            self.names[p.key] = str(raw_name)

    def _coerce(self, raw: Any, p: _Param, name: str) -> Any:
        where = f"{self.src.path}: {name}"
        if p.key in UNUSED:
            return raw  # no mcl key: its value is only listed
        if p.kind is float:
            return finite_number(raw, where, MclError)
        if p.kind is int:
            if isinstance(raw, float) and raw.is_integer():
                return int(raw)
            if isinstance(raw, bool) or not isinstance(raw, int):
                raise MclError(f"{where}: expected an integer, got {short_repr(raw)}")
            return raw
        if p.kind is bool:
            if isinstance(raw, str) and raw.lower() in ("true", "false"):
                return raw.lower() == "true"
            if not isinstance(raw, bool):
                raise MclError(f"{where}: expected true or false, got {short_repr(raw)}")
            return raw
        if not isinstance(raw, str) or not raw.strip():
            raise MclError(f"{where}: expected a name, got {short_repr(raw)}")
        return raw.strip()

    # -- writing

    def set(self, key: str, value: Any, comment: str, *sources: str) -> None:
        self.entries.append(_Entry(key, value, comment, tuple((self.name(s), self.get(s)) for s in sources)))
        self.used.update(sources)

    def note(self, text: str, *keys: str) -> None:
        self.notes.append(text)
        self.used.update(keys)

    def note_unused(self, keys: tuple, by: str) -> None:
        given = [k for k in keys if self.given(k)]
        if given:
            self.note(f"{', '.join(map(self.said, given))}: used by {by} only: not used", *given)

    def warn(self, text: str) -> None:
        self.warnings.append(text)

    # -- the mapping

    def convert(self) -> None:
        self.particles()
        self.motion()
        self.sensor()
        self.recovery()
        self.start()
        self.names_and_frames()
        for key, value in self.values.items():
            if key not in self.used:
                why = UNUSED.get(key, "")
                self.unused.append(f"{self.name(key)} {_num(value)}{f' ({why})' if why else ''}")

    def particles(self) -> None:
        group = ("max_particles", "min_particles", "pf_err", "pf_z")
        if any(map(self.given, group)):
            hi, lo = self.get("max_particles"), self.get("min_particles")
            if self.flavour == NAV2:  # amcl_node.cpp initParameters' semantic checks, in their order
                if isinstance(hi, int) and hi < 0:
                    self.warn(f"{self.said('max_particles')} is negative: nav2 sets it to 2000, and so does this config")
                    hi = 2000
                if isinstance(lo, int) and lo < 0:
                    self.warn(f"{self.said('min_particles')} is negative: nav2 sets it to 500, and so does this config")
                    lo = 500
            if isinstance(hi, int) and isinstance(lo, int) and lo > hi:
                if self.flavour == NAV2:
                    self.warn(f"{self.name('min_particles')} {lo} is above {self.name('max_particles')} {hi}: nav2 "
                              "raises max_particles to it, and so does this config")
                    hi = lo
                else:  # the check that raises it is in reconfigureCB, whose first call (at start) returns at once
                    self.warn(f"{self.name('min_particles')} {lo} is above {self.name('max_particles')} {hi}: ROS 1 "
                              "amcl's set never grows past max_particles (pf.c clamps the KLD count to it last), so "
                              f"this config's min_particles is {hi}")
                    lo = hi
            self.set("filter.particles", hi, f"{self.said('max_particles')}: with kld, the maximum and the count "
                     "drawn at start", "max_particles")
            self.set("filter.min_particles", lo, self.said("min_particles"), "min_particles")
            self.set("filter.kld", True, "AMCL always sizes its set by KLD sampling (pf.c pf_resample_limit)")
            self.set("filter.kld_epsilon", self.get("pf_err"), self.said("pf_err"), "pf_err")
            z = self.get("pf_z")
            delta = 0.5 * math.erfc(z / math.sqrt(2.0))
            self.set("filter.kld_delta", float(f"{delta:.4g}"),
                     f"{self.said('pf_z')} is the normal quantile z_(1-delta) itself: delta = 1 - Phi(z)", "pf_z")
        gating = ("update_min_d", "update_min_a")
        for key in gating if any(map(self.given, gating)) else ():  # a group: AMCL's default fills the other
            extra = (" (AMCL updates when |dx| or |dy| exceeds it, mcl when the distance does)"
                     if key == "update_min_d" else "")
            self.set(f"filter.{key}", self.get(key), f"{self.said(key)}{extra}", key)
        if self.given("selective_resampling") and self.get("selective_resampling"):
            self.set("filter.resample_threshold", 0.5, "selective_resampling true: resample when N_eff < N / 2",
                     "selective_resampling")
        if self.given("resample_interval"):
            self.note(f"{self.said('resample_interval')}: mcl has no resampling interval; it resamples when the "
                      "effective sample size falls below filter.resample_threshold x N (0.5; 1.0 resamples at every "
                      "update, as resample_interval 1)", "resample_interval")

    def motion(self) -> None:
        alphas = ("alpha1", "alpha2", "alpha3", "alpha4")
        model_given = self.given("robot_model_type")
        if not (model_given or any(map(self.given, alphas))):
            if self.given("alpha5"):
                self.note(f"{self.said('alpha5')}: AMCL's omni models only (mcl's motion.alpha5 is the velocity "
                          "model's, another thing): not used", "alpha5")
            return
        model = str(self.get("robot_model_type"))
        kind = model.lower()
        said = self.said("robot_model_type")
        if kind == "diff-corrected" or "differential" in kind:  # nav2: differential, nav2_amcl::DifferentialMotionModel
            how = "sample_motion_model_odometry with std sqrt(alpha1 rot^2 + alpha2 trans^2): the variance form"
        elif kind == "diff":
            d = float(self.get("update_min_d")) or 0.2
            a3 = float(self.get("alpha3"))
            wider = (f", so at a {d:g} m step ({self.name('update_min_d')}) mcl's translation noise from alpha3 "
                     f"is {1 / (math.sqrt(a3) * d):.1f} times AMCL's" if a3 > 0 and d > 0 else "")
            how = ("ROS 1's uncorrected model, whose std is what the variance form's variance is: the alphas "
                   "kept, retune them")
            self.warn(f"{said}: ROS 1's uncorrected model takes alpha1 rot^2 + alpha2 trans^2 as the std "
                      f"(ros-planning/navigation#20), mcl as the variance (as diff-corrected and nav2 do); the alphas "
                      f"are kept{wider}: retune them (mcl calibrate motion)")
        elif "omni" in kind and self.flavour == ROS1:
            how = ("ROS 1 AMCL's omni model (mcl.motion.OmniMotionModel): its alpha1 (translation and strafe noise "
                   "from rotation) and alpha4 (rotation noise from rotation) are mcl's motion.alpha4 and motion.alpha1")
            if kind == "omni":
                self.warn(f"{said}: ROS 1's uncorrected omni takes alpha3 trans^2 + alpha1 rot^2 itself as the std "
                          "(ros-planning/navigation#20), mcl as the variance (as omni-corrected and nav2 do): the "
                          "alphas are kept, retune them")
        elif "omni" in kind:
            how = ("nav2's OmniMotionModel (mcl.motion.OmniMotionModel): the book's roles, alpha for alpha (alpha4, "
                   "translation noise from rotation, is the strafe's too)")
        else:
            how = "not an AMCL motion model: the alphas are kept for the differential one"
            self.warn(f"{said}: not an AMCL motion model (diff, diff-corrected, omni, omni-corrected; nav2: "
                      "nav2_amcl::DifferentialMotionModel, nav2_amcl::OmniMotionModel): read as differential")
        self.set("motion.model", "omni" if "omni" in kind else "odometry", f"{said}: {how}", "robot_model_type")
        self.set("motion.noise_form", "variance", "sigma^2 = alpha1 rot^2 + alpha2 trans^2 (Table 5.6)")
        self.set("motion.noise_step", 0.0, "the book's trans^2 at every step length, as AMCL draws it once an update")
        what = {"alpha1": "rotation noise from rotation", "alpha2": "rotation noise from translation",
                "alpha3": "translation noise from translation", "alpha4": "translation noise from rotation"}
        # ROS 1 AMCL's omni models (amcl_odom.cpp): rot std from alpha4 rot^2 + alpha2 trans^2, trans and strafe std
        # from alpha3 trans^2 (alpha5 trans^2) + alpha1 rot^2: alpha1 and alpha4 swap roles against the differential
        # model. nav2's (omni_motion_model.cpp) keeps the book's: rot from alpha1 rot^2, trans and strafe from alpha4.
        source = {"alpha1": "alpha4", "alpha4": "alpha1"} if "omni" in kind and self.flavour == ROS1 else {}
        for a in alphas:
            src = source.get(a, a)
            self.set(f"motion.{a}", self.get(src), f"{self.said(src)}: {what[a]}", src)
        if "omni" in kind:
            self.set("motion.alpha_strafe", self.get("alpha5"), f"{self.said('alpha5')}: strafe noise from "
                     "translation", "alpha5")
        elif self.given("alpha5"):
            self.note(f"{self.said('alpha5')}: AMCL's omni models only (mcl's motion.alpha5 is the velocity model's, "
                      "another thing): not used", "alpha5")

    def sensor(self) -> None:
        model = str(self.get("laser_model_type"))
        if model not in ("beam", "likelihood_field", "likelihood_field_prob"):
            self.warn(f"{self.said('laser_model_type')}: not an AMCL laser model (beam, likelihood_field, "
                      "likelihood_field_prob); AMCL falls back to likelihood_field, and so does this config")
            model = "likelihood_field"
        field_keys = ("z_hit", "z_rand", "sigma_hit")
        beam_keys = ("z_hit", "z_short", "z_max", "z_rand", "sigma_hit", "lambda_short")
        skip_keys = ("do_beamskip", "beam_skip_distance", "beam_skip_threshold", "beam_skip_error_threshold")
        touched = [k for k in (*beam_keys, "laser_likelihood_max_dist", "laser_model_type", *skip_keys)
                   if self.given(k)]
        if touched:
            mcl_model = "beam" if model == "beam" else "likelihood_field"
            self.set("sensor.model", mcl_model, self.said("laser_model_type"), "laser_model_type")
        if self.given("max_beams"):
            self.set("sensor.max_beams", self.get("max_beams"), self.said("max_beams"), "max_beams")
        for key, mcl_key in (("laser_min_range", "sensor.range_min"), ("laser_max_range", "sensor.range_max")):
            if self.given(key):
                if self.get(key) > 0:
                    self.set(mcl_key, self.get(key), self.said(key), key)
                else:
                    own = " (a reading at the log's or bag's own maximum is no return too)" if "max" in key else ""
                    self.note(f"{self.said(key)}: the scan's own range: mcl's {mcl_key} kept{own}", key)
        if not touched:
            return
        if model == "beam":
            if any(map(self.given, beam_keys)):
                self.weights("sensor.beam", beam_keys, ("z_hit", "z_short", "z_max", "z_rand"))
                self.note("AMCL's beam model leaves p_short unnormalised (lambda e^(-lambda z)); mcl's, the book's, "
                          "divides it by 1 - e^(-lambda z*): short readings weigh more where the map's range z* is "
                          "short")
            self.note_unused(("laser_likelihood_max_dist", *skip_keys), "AMCL's likelihood fields")
            self.note("AMCL's beam model combines the beams as 1 + sum p^3 (amcl_laser.cpp, an ad hoc rule); mcl "
                      "multiplies them (the book's product): its weights are sharper (sensor.exponent < 1 tempers "
                      "them)")
            return
        if any(map(self.given, field_keys)):
            self.weights("sensor.likelihood_field", field_keys, ("z_hit", "z_rand"))
            self.note_rand_range()
        if self.given("laser_likelihood_max_dist"):
            self.set("sensor.likelihood_field.likelihood_max_dist", self.get("laser_likelihood_max_dist"),
                     self.said("laser_likelihood_max_dist"), "laser_likelihood_max_dist")
        self.set("sensor.likelihood_field.interior", "zero", "AMCL's field: d = 0 inside occupied cells (mcl's "
                 "default, depth, tracked better on its synthetic worlds: README, 'Inside walls')")
        self.note_unused(("z_short", "z_max", "lambda_short"), "AMCL's beam model")
        if model == "likelihood_field_prob":
            on = bool(self.get("do_beamskip"))
            self.set("sensor.beam_skip", on, f"{self.said('do_beamskip')}: likelihood_field_prob skips beams only "
                     "with it", "do_beamskip")
            self.set("sensor.beam_skip_rule", "amcl", "likelihood_field_prob: every beam that too few particles "
                     "explain is skipped, once converged")
            for key in skip_keys[1:]:
                self.set(f"sensor.{key}", self.get(key), self.said(key), key)
            if on:
                self.note("beam skipping: AMCL counts the particles that explain a beam, mcl weighs them; AMCL "
                          "skips once every particle is within 0.5 m of the mean (pf_update_converged), mcl once the "
                          "heaviest cluster holds half the weight within beam_skip_distance")
        else:
            if self.given("do_beamskip") and self.get("do_beamskip"):
                self.warn(f"{self.said('do_beamskip')}: AMCL skips beams only with laser_model_type "
                          f"likelihood_field_prob (here {model}): not used")
            self.note_unused(skip_keys, "AMCL's likelihood_field_prob")
            self.note("AMCL's likelihood_field combines the beams as 1 + sum p^3 (amcl_laser.cpp, an ad hoc rule); "
                      "mcl multiplies them, as the book and AMCL's likelihood_field_prob do: its weights are sharper "
                      "(sensor.exponent < 1 tempers them)")

    def note_rand_range(self) -> None:
        """AMCL's z_rand / range_max uses the laser's range (the scan's range_max, laser_max_range where that is
        smaller), mcl's sensor.range_max: a note with the factor that makes them one (a stock nav2 file's 100 m
        against a 12 m laser is 8.3 times lower a floor)."""
        given = self.given("laser_max_range") and self.get("laser_max_range") > 0
        if given:
            here = f"{_num(self.get('laser_max_range'))} m, from {self.name('laser_max_range')}"
            r = float(self.get("laser_max_range"))
        else:
            from mcl.config import SensorConfig

            r = float(SensorConfig().range_max)
            here = f"{_num(r)} m, mcl's default"
        self.note(f"AMCL divides z_rand by the laser's range (the scan's range_max, or laser_max_range where "
                  f"smaller); mcl by sensor.range_max ({here}): for a laser of R m mcl's floor is R/{_num(r)} of "
                  f"AMCL's. To score as AMCL did, set sensor.range_max to the laser's range (a reading at it is no "
                  f"return, as in AMCL), or z_rand to z_rand x {_num(r)}/R with z_hit scaled so they sum to 1")

    def weights(self, block: str, keys: tuple, mixture: tuple) -> None:
        """The mixture weights of ``block``, AMCL's unnormalised hit Gaussian made a density (x sqrt(2 pi) sigma)
        and the weights scaled to sum to 1: the same p(z) up to a factor common to every particle. Values mcl
        refuses (a negative weight, sigma <= 0, all zero) go through as they are, for its check to name."""
        w = {k: float(self.get(k)) for k in mixture}
        sigma = float(self.get("sigma_hit"))
        ok = sigma > 0 and all(v >= 0 for v in w.values())
        if ok:
            w["z_hit"] *= math.sqrt(2 * math.pi) * sigma
            total = sum(w.values())
            ok = total > 0
            if ok:
                w = {k: v / total for k, v in w.items()}
        for k in keys:
            if k in mixture:
                how = ("" if not ok else ": AMCL's unnormalised hit Gaussian x sqrt(2 pi) sigma_hit, then the "
                       "weights scaled to sum to 1 (AMCL's p(z) where sensor.range_max is the laser's range: see the notes)" if k == "z_hit" else
                       ": scaled with z_hit (see there)")
                self.set(f"{block}.{k}", float(f"{w[k]:.6g}") if ok else self.get(k), f"{self.said(k)}{how}", k)
            else:
                self.set(f"{block}.{k}", self.get(k), self.said(k), k)

    def recovery(self) -> None:
        keys = ("recovery_alpha_slow", "recovery_alpha_fast")
        if not any(map(self.given, keys)):
            return
        slow, fast = self.get(keys[0]), self.get(keys[1])
        said = f"{self.said(keys[0])}, {self.said(keys[1])}"
        if slow > 0 and fast > 0:
            self.set("filter.recovery", "augmented", f"{said}: AMCL's augmented MCL (pf.c: random poses with "
                     "probability 1 - w_fast / w_slow)", *keys)
            self.set("filter.recovery_alpha_slow", slow, self.said(keys[0]), keys[0])
            self.set("filter.recovery_alpha_fast", fast, self.said(keys[1]), keys[1])
        elif slow == 0 and fast == 0:
            self.note(f"{said}: AMCL injects no random poses. mcl's default recovery (lost: only while the quality "
                      "signal says the filter is lost) is kept; filter.recovery: false is AMCL's", *keys)
        else:
            self.warn(f"{said}: one rate 0 freezes that average at its first value in AMCL; mcl's augmented MCL "
                      "needs both above 0: not mapped (mcl's default recovery kept)")
            self.used.update(keys)

    def start(self) -> None:
        if self.given("random_seed"):
            seed = self.get("random_seed")
            if isinstance(seed, int) and not isinstance(seed, bool) and seed >= 0:
                self.set("seed", seed, self.said("random_seed"), "random_seed")
            else:
                self.note(f"{self.said('random_seed')}: a new seed every run in nav2; mcl's runs repeat, its seed "
                          "kept", "random_seed")
        if self.flavour == NAV2:
            pose = ("initial_pose.x", "initial_pose.y", "initial_pose.yaw")
            if self.given("set_initial_pose") and self.get("set_initial_pose"):
                self.set("filter.initial_pose", [float(self.get(k)) for k in pose],
                         f"set_initial_pose true: {', '.join(self.said(k) for k in pose)}", "set_initial_pose", *pose)
                self.note("nav2 starts from initial_pose with a zero covariance (every particle on the pose): mcl's "
                          "filter.initial_std (0.1 m, 0.1 m, 0.1 rad) kept")
            elif any(map(self.given, pose)):
                self.note(f"{', '.join(self.said(k) for k in pose if self.given(k))}: not used, as in nav2 without "
                          "set_initial_pose: true (mcl starts from the bag's /initialpose, else globally)",
                          *pose)
            return
        pose = ("initial_pose.x", "initial_pose.y", "initial_pose.yaw")
        cov = ("initial_cov_xx", "initial_cov_yy", "initial_cov_aa")
        if any(map(self.given, pose)):
            self.set("filter.initial_pose", [float(self.get(k)) for k in pose],
                     ", ".join(self.said(k) for k in pose), *pose)
        elif any(map(self.given, cov)):
            self.note("no initial_pose_x/y/a: ROS 1 amcl starts at (0, 0, 0); mcl starts from the bag's "
                      "/initialpose or --initial-pose, else globally")
        if any(map(self.given, (*pose, *cov))):
            stds = []
            for k in cov:
                v = float(self.get(k))
                if v < 0:
                    raise MclError(f"{self.src.path}: {self.name(k)}: {v:g} is a variance, it must be >= 0")
                stds.append(math.sqrt(v))
            self.set("filter.initial_std", stds, "square roots of " + ", ".join(self.said(k) for k in cov), *cov)

    def names_and_frames(self) -> None:
        for key, mcl_key in (("odom_frame_id", "frames.odom"), ("base_frame_id", "frames.base")):
            if self.given(key):
                self.set(mcl_key, str(self.get(key)).lstrip("/"), self.said(key), key)
        ns = self.src.ns
        topics = []
        for topic, key in (("scan", "scan_topic"), ("map", "map_topic")):
            if self.given(key):
                topics.append((f"topics.{topic}", _resolve(str(self.get(key)), ns), self.said(key), key))
            elif topic in self.src.remaps:
                to = self.src.remaps[topic]
                topics.append((f"topics.{topic}", to, f"<remap from={topic}>" + (f" in /{ns}" if ns else ""), None))
            elif ns:
                topics.append((f"topics.{topic}", _resolve(topic, ns), f"the node's namespace /{ns}", None))
        for mcl_key, topic, said, key in topics:
            name = topic if topic.startswith("/") else "/" + topic
            rel = " (relative: in the root namespace)" if name != topic else ""
            self.set(mcl_key, name, f"{said}{rel}", *((key,) if key else ()))

    # -- the text

    def text(self) -> str:
        label = {ROS1: "ROS 1 amcl", NAV2: "ROS 2 nav2_amcl"}[self.flavour]
        lines = [f"# mcl config from the {label} parameters of {self.src.path.name} ({self.src.where}), by",
                 "# `mcl config from-amcl`. It sets only these keys; the others are configs/default.yaml's. Run it with",
                 "#   mcl run THIS.yaml --bag B [--map M.yaml]    (or merge the keys into your own config)"]
        tree: dict = {}
        for e in self.entries:
            *sections, leaf = e.key.split(".")
            node = tree
            for s in sections:
                node = node.setdefault(s, {})
            node[leaf] = e

        def emit(node: dict, indent: int) -> None:
            for k, v in node.items():
                if isinstance(v, dict):
                    lines.append(" " * indent + f"{k}:")
                    emit(v, indent + 2)
                else:
                    head = " " * indent + f"{k}: {_fmt(v.value)}"
                    col = max(34, len(head) + 2)
                    parts = textwrap.wrap(v.comment, WIDTH - col - 2, break_on_hyphens=False) or [""]
                    lines.append(f"{head:<{col}}# {parts[0]}")
                    lines.extend(f"{'':<{col}}# {part}" for part in parts[1:])

        order = ("seed", "filter", "motion", "sensor", "topics", "frames")
        emit({k: tree[k] for k in sorted(tree, key=order.index)}, 0)
        if self.notes:
            lines.append("# Notes:")
            for n in self.notes:
                lines += textwrap.wrap(n, WIDTH, initial_indent="# - ", subsequent_indent="#   ",
                                       break_on_hyphens=False)
        if self.unused:
            lines += textwrap.wrap(f"Not used (no mcl counterpart): {', '.join(self.unused)}", WIDTH,
                                   initial_indent="# ", subsequent_indent="#   ", break_on_hyphens=False)
        return "\n".join(lines) + "\n"


@dataclass
class Conversion:
    """What :func:`convert` returns: the config's YAML ``text``, its ``keys`` (dotted mcl key -> value) and the
    ``warnings`` (one line each, naming the file)."""

    text: str
    keys: dict
    warnings: list


def convert(path: str | Path) -> Conversion:
    """Read AMCL parameters from ``path`` and return the mcl config they correspond to, checked by
    :func:`mcl.config.load_config` (a value it refuses is an MclError naming the AMCL parameter)."""
    from mcl.config import load_config

    src = read_source(path)
    c = _Converter(src)
    c.read()
    if not any(p.key not in _WEAK for p in map(_BY_KEY.get, c.values)):
        why = [w for w in c.warnings if "cannot be resolved" in w or "not read" in w]
        raise MclError(f"{src.path}: no AMCL parameters found in {src.where}"
                       + (f" ({'; '.join(why)}: give that file)" if why else ""))
    c.convert()
    text = c.text()
    with tempfile.TemporaryDirectory() as tmp:
        f = Path(tmp) / "from-amcl.yaml"
        f.write_text(text, encoding="utf-8")
        try:
            load_config(f)
        except ConfigError as e:
            msg = re.sub(rf"^{re.escape(str(f))}(:\d+)?: ", "", str(e))  # (the file's line: of a temporary file)
            entry = next((x for x in c.entries if msg.startswith(x.key + ":")), None) or next(
                (x for x in c.entries if re.search(rf"(?<![\w.]){re.escape(x.key)}(?!\w)", msg)), None)
            if entry is None or not entry.sources:
                raise MclError(f"{src.path}: the converted config is refused: {msg}") from None
            given = ", ".join(f"{n} {_num(v)}" for n, v in entry.sources)
            raise MclError(f"{src.path}: {given}: {msg}") from None
    return Conversion(text, {e.key: e.value for e in c.entries},
                      [f"{src.path}: {w}" for w in c.warnings])
