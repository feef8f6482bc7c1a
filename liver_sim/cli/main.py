"""The ``liver-sim`` command line.

Each subcommand is an ``add_*_command(subparsers)`` function that declares its
arguments and sets ``handler`` to a function ``handler(args) -> int``; list it in
:data:`COMMANDS`.  A refused input ends the command with exit status 2 and
``liver-sim: error: <file>: <defect>`` on stderr.  A command that starts ROS (:func:`starts_ros`)
keeps DDS on this machine unless ``--discovery-range`` or ROS_AUTOMATIC_DISCOVERY_RANGE says otherwise,
and says its domain and range first.

Each handler imports the modules of its command when it runs (marked where it does): they load what other
commands never need (numba's kernels, rclpy and the message packages, matplotlib), so that `liver-sim
--help` and a mesh command start at once.
"""
from __future__ import annotations

import argparse
import json
import signal
import sys
import time
from pathlib import Path

from liver_sim.base.emulated_link import LINK_PARAMETERS, LinkSettings
from liver_sim.base.parameters import check_parameter
from liver_sim.base.process_settings import DISCOVERY_RANGES, keep_dds_local, use_dds_profile
from liver_sim.cli.arguments import add_tools_argument, positive_float, positive_int
from liver_sim.cli.bench import add_bench_command
from liver_sim.cli.sessions import (
    add_bag_command,
    add_fig8_command,
    add_record_command,
    add_replay_command,
    add_report_command,
    add_resimulate_command,
)
from liver_sim.mesh.io import (
    CAPSULE_REGION,
    ORGAN_SIZE_RANGE_M,
    PARENCHYMA_REGION,
    WRITE_SUFFIXES,
    checked_output_path,
    load_mesh,
    write_mesh,
)
from liver_sim.mesh.label_volume import is_segmentation_path
from liver_sim.mesh.liver_shape import build_liver, default_liver
from liver_sim.mesh.tetmesh import TetMesh
from liver_sim.nodes.occupants import DomainOccupied
from liver_sim.running.launcher import NodeFailure
from liver_sim.sessions.bag import STORAGES
from liver_sim.view.defaults import DEFAULT_HOST, DEFAULT_PORT, VIEW_RATE_HZ

PROG = "liver-sim"
#: Exit status of a command that refused its input.
EXIT_REFUSED = 2
#: Exit status of a command whose node processes failed (NodeFailure).
EXIT_NODE_FAILED = 1


def add_scale_argument(parser) -> None:
    """--scale FACTOR: the factor from the mesh file's units to metres."""
    parser.add_argument("--scale", type=positive_float, default=1.0, metavar="FACTOR",
                        help="multiply the file's coordinates by FACTOR to get metres, before anything else "
                             "(0.01: file in centimetres, 0.001: millimetres; default: 1, metres). A mesh "
                             f"not {ORGAN_SIZE_RANGE_M[0]:g}-{ORGAN_SIZE_RANGE_M[1]:g} m across is refused")


def add_mesh_command(commands) -> None:
    """``liver-sim mesh info|build``: describe or convert a mesh (default: the built-in liver)."""
    mesh_parser = commands.add_parser("mesh", help="describe or write tetrahedral meshes")
    actions = mesh_parser.add_subparsers(dest="action", required=True, metavar="ACTION")

    def add_source_arguments(parser) -> None:
        parser.add_argument("path", nargs="?", metavar="PATH",
                            help="volume mesh (.msh .vtu .vtk .mesh) or closed surface "
                                 "(.stl .obj .ply .off); build also takes a segmentation (.nii .nii.gz .nrrd "
                                 ".seg.nrrd, docs/segmentation.md); default: the built-in liver")
        parser.add_argument("--target-tets", type=positive_int, metavar="N",
                            help="tet count aimed at when tetrahedralising a surface or the "
                                 "built-in liver (volume meshes are used as they are)")
        add_scale_argument(parser)

    info = actions.add_parser("info", help="print size, volume, quality and hash of a mesh")
    add_source_arguments(info)
    info.add_argument("--json", action="store_true", help="print one JSON object")
    info.set_defaults(handler=mesh_info)

    build = actions.add_parser("build", help="write the tet mesh with its skin tagged")
    add_source_arguments(build)
    build.add_argument("--out", required=True, metavar="FILE",
                       help=f"output file, format by extension: {' '.join(WRITE_SUFFIXES)}")
    build.add_argument("--json", action="store_true", help="print what was written as one JSON object")
    build.add_argument("--label", type=int, default=None, metavar="N",
                       help="segmentation: the organ's label (default: the only non-zero label)")
    build.add_argument("--support-label", type=int, default=None, metavar="M",
                       help="segmentation: hold the organ where label M (e.g. the vena cava) touches it, instead "
                            "of the bare area")
    build.add_argument("--support-regions", type=float, nargs="+", default=None, metavar="V",
                       help="segmentation: hold the organ by these spheres instead, five numbers each: x y z "
                            "radius (m, liver frame) and stiffness per skin area (N/m^3)")
    build.set_defaults(handler=mesh_build)


def mesh_from_args(args) -> TetMesh:
    """The mesh named by PATH in metres (its coordinates × --scale), or the built-in liver (rebuilt when
    --target-tets is given)."""
    if args.path is not None:
        return load_mesh(args.path, args.target_tets, args.scale)
    if args.scale != 1.0:
        raise ValueError("--scale applies to a mesh file (PATH); the built-in liver is in metres")
    if args.target_tets is not None:
        return build_liver(args.target_tets)
    return default_liver()


def mesh_info(args) -> int:
    """Print :meth:`TetMesh.summary` (plus the volume in litres), as text or JSON."""
    info = mesh_from_args(args).summary()
    info["volume_l"] = info["volume_m3"] * 1e3
    if args.json:
        print(json.dumps(info))
        return 0
    (lo, hi), size = info["bounds_m"], info["size_m"]
    print(f"source          {info['source']}")
    print(f"nodes           {info['nodes']}")
    print(f"tetrahedra      {info['tetrahedra']}")
    print(f"skin triangles  {info['skin_triangles']}")
    print(f"volume          {info['volume_m3']:.6g} m^3 ({info['volume_l']:.4g} L)")
    print("bounding box    " + "  ".join(f"{a}: {l:.4g} .. {h:.4g}" for a, l, h in zip("xyz", lo, hi)) + " m")
    print("size            " + " x ".join(f"{s:.4g}" for s in size) + " m")
    print(f"dihedral angles {info['min_dihedral_deg']:.2f} .. {info['max_dihedral_deg']:.2f} deg")
    print(f"watertight      {'yes' if info['watertight'] else 'no'}")
    print(f"sha256          {info['sha256']}")
    return 0


def mesh_build(args) -> int:
    """Write the mesh to --out and say what was written."""
    out = checked_output_path(args.out)  # refuse a bad extension before building anything
    if args.path is not None and is_segmentation_path(args.path):
        return segmentation_build(args)
    if args.label is not None or args.support_label is not None or args.support_regions is not None:
        raise ValueError("--label, --support-label and --support-regions apply to a segmentation PATH (.nii "
                         ".nii.gz .nrrd .seg.nrrd)")
    mesh = mesh_from_args(args)
    write_mesh(mesh, out)
    if args.json:
        print(json.dumps({**mesh.summary(), "out": str(out)}))
        return 0
    print(f"wrote {out}: {len(mesh.points)} nodes, {len(mesh.tets)} tetrahedra (region "
          f"{PARENCHYMA_REGION} 'parenchyma'), {len(mesh.skin)} skin triangles (region "
          f"{CAPSULE_REGION} 'capsule'), sha256 {mesh.sha256}")
    return 0


def segmentation_build(args) -> int:
    """`mesh build SEGMENTATION`: the mesh and its support file, a progress bar on stderr, the summary."""
    # this command's own modules, loaded when it runs (module docstring)
    from liver_sim.mesh.anatomical_support import user_regions
    from liver_sim.mesh.segmentation_build import build_from_segmentation

    if args.scale != 1.0:
        raise ValueError("--scale applies to mesh files; a segmentation's header gives its spacing in millimetres")
    regions = user_regions(args.support_regions) if args.support_regions is not None else None
    bar = ProgressBar(sys.stderr)
    try:
        summary = build_from_segmentation(args.path, args.out, args.label, args.target_tets, args.support_label,
                                          regions, bar.show)
    finally:
        bar.close()
    for warning in summary["warnings"]:
        print(f"{PROG}: warning: {warning}", file=sys.stderr)
    print(json.dumps(summary) if args.json else segmentation_summary(summary))
    return 0


def segmentation_summary(summary: dict) -> str:
    """The lines `mesh build SEGMENTATION` prints."""
    others = ", ".join(f"{v:.3g}" for v in summary["other_components_ml"]) or "none"
    lines = [
        f"read            {summary['source']}, label {summary['label']}, axes {summary['axes']}",
        f"voxels          {' x '.join(map(str, summary['voxels']))}, spacing "
        f"{' x '.join(f'{v:g}' for v in summary['spacing_mm'])} mm",
        f"label           {summary['label_voxels']} voxels, {summary['label_volume_ml']:.4g} mL; kept "
        f"{summary['kept_volume_ml']:.4g} mL (largest part, {summary['cavities_filled_ml']:.3g} mL of cavities "
        f"filled); other parts dropped (mL): {others}",
        f"mesh            {summary['tetrahedra']} tetrahedra, {summary['nodes']} nodes, {summary['mesh_volume_ml']:.4g}"
        f" mL, min dihedral {summary['min_dihedral_deg']:.1f} deg",
        f"surface         largest distance to the label's boundary {summary['max_surface_distance_voxels']:.2f} "
        f"voxels ({summary['max_surface_distance_mm']:.2f} mm)",
        f"placement       {summary['placement']}, at LPS "
        f"({', '.join(f'{v:g}' for v in summary['lps_origin_mm'])}) mm in the scanner",
        f"{summary['support']}: {summary['support_skin_nodes']} skin nodes held",
        f"wrote           {summary['out']} and {summary['support_file']} in {summary['seconds']:.1f} s",
    ]
    return "\n".join(lines)


class ProgressBar:
    """A one-line bar of a build's stages on a terminal (stage lines elsewhere): show(step, total, text)."""

    WIDTH = 24

    def __init__(self, stream):
        self.stream = stream
        self.live = stream.isatty()

    def show(self, step: int, total: int, text: str) -> None:
        done = self.WIDTH * (step - 1) // total
        line = f"[{'#' * done}{'.' * (self.WIDTH - done)}] {step}/{total} {text}"
        print(f"\r{line:<60}" if self.live else line, end="" if self.live else "\n", file=self.stream, flush=True)

    def close(self) -> None:
        if self.live:
            print(file=self.stream, flush=True)


def add_validate_command(commands) -> None:
    """``liver-sim validate [behaviour|indentation] [--sizes N …] [--radius M] [--depths M …] [--json] [--out DIR]``:
    behaviours B1–B4, traction
    with the liver's materials and the local model's continuity; or the sphere pressed into a block (indentation),
    each figure beside its threshold."""
    parser = commands.add_parser("validate", help="the paper's behaviours (B1-B4), traction with the liver's "
                                 "materials and the local model's continuity, or (indentation) a sphere pressed "
                                 "into a block against Hertz, as figures against thresholds")
    parser.add_argument("section", nargs="?", choices=("behaviour", "indentation"), default="behaviour",
                        help="behaviour (default): B1-B4, R1 with the materials, continuity; indentation: a sphere "
                             "(the tool's, 15 mm) pressed 1-5 mm into a bonded 12 x 12 x 6 cm block, per mesh size, "
                             "against Hertz and a linear P1 solve on the same tets, and the held tool's settling")
    parser.add_argument("--sizes", type=positive_int, nargs="+", default=None, metavar="TETS",
                        help="indentation: the block's mesh sizes (tetrahedra; default 5000 20000 80000)")
    parser.add_argument("--radius", type=positive_float, default=None, metavar="M",
                        help="indentation: the sphere's radius (m; default 0.015, the tool's; 0.005: a probe tip)")
    parser.add_argument("--depths", type=positive_float, nargs="+", default=None, metavar="M",
                        help="indentation: the depths the sphere is stepped to (m; default 0.001 ... 0.005)")
    parser.add_argument("--json", action="store_true", help="print the figures as JSON on stdout (progress on stderr)")
    parser.add_argument("--out", type=Path, default=None, metavar="DIR",
                        help="write the plots and validate.json (indentation.json) to DIR")
    parser.set_defaults(handler=validate)


def validate(args) -> int:
    # this command's own modules, loaded when it runs (module docstring)
    stream = sys.stderr if args.json else sys.stdout

    def progress(text):
        print(text, file=stream, flush=True)

    if args.section == "indentation":
        from liver_sim.studies.indentation import DEFAULT_SIZES, DEPTHS_M, SPHERE_RADIUS_M, main_indentation
        depths = tuple(sorted(args.depths or DEPTHS_M))
        return main_indentation(tuple(args.sizes or DEFAULT_SIZES), args.json, args.out, progress=progress,
                                radius_m=args.radius or SPHERE_RADIUS_M, depths_m=depths)
    for option in ("sizes", "radius", "depths"):
        if getattr(args, option) is not None:
            raise SystemExit(f"{PROG}: error: --{option} is for validate indentation")
    from liver_sim.studies.validate import main_validate
    return main_validate(args.json, args.out, progress=progress)


def add_warm_command(commands) -> None:
    """``liver-sim warm``: compile the physics kernels into numba's on-disk cache."""
    parser = commands.add_parser("warm", help="compile the physics' numba kernels into their on-disk cache, as the "
                                              "first start of liver_physics would (about 30 s of one core, once)")
    parser.set_defaults(handler=warm)


def warm(args) -> int:
    # this command's own modules, loaded when it runs (module docstring)
    from liver_sim.physics.parameters import PhysicsParameters, build_model
    from liver_sim.physics.settings import INTEGRATORS

    started = time.monotonic()
    defaults = PhysicsParameters.defaults()
    for integrator in INTEGRATORS:  # the implicit frame's kernels and the explicit one's
        build_model(defaults.replace(integrator=integrator))  # builds the default liver and warms it up
    print(f"the physics kernels are compiled and cached ({time.monotonic() - started:.1f} s)")
    return 0


def add_traction_command(commands) -> None:
    """``liver-sim traction [--out DIR]``: the traction test of Figs. 4–5."""
    parser = commands.add_parser("traction", help="traction test of a cylinder beside the connector law (Figs. 4-5)")
    parser.add_argument("--out", type=Path, default=Path("out/traction"), help="output folder (default: %(default)s)")
    parser.set_defaults(handler=traction)


def traction(args) -> int:
    # this command's own modules, loaded when it runs (module docstring)
    from liver_sim.studies.traction import run_traction, write_traction

    def report(level, levels, force, elongation):
        print(f"  level {level:2d}/{levels}: {force:8.4f} N -> elongation {elongation * 100:6.2f} %", flush=True)

    print("pulling a cylinder (top fixed, equal forces on the bottom nodes) to static equilibrium", flush=True)
    result = run_traction(progress=report)
    csv_path, png_path = write_traction(result, args.out)
    print(f"wrote {csv_path} and {png_path}")
    return 0


def add_demo_command(commands) -> None:
    """``liver-sim demo [--scenario press|tear|cut] [--mesh PATH [--scale F]] [--duration S] [--out DIR] [--offline]
    [--record [--storage …]] [--link-delay S [--link-jitter S] [--link-loss F]] [--tools 1|2]``: the closed-loop
    demo."""
    parser = commands.add_parser("demo", help="the four nodes in closed loop with a simulated PHANToM "
                                              "pressing the default liver or --mesh (--offline: the model alone, "
                                              "no ROS)")
    parser.add_argument("--scenario", choices=("press", "tear", "cut"), default="press",
                        help="press: press, slide and release (default); tear: grasp and pull until the liver "
                             "tears; cut: cut the liver along the tool path; tear and cut draw it before and after")
    parser.add_argument("--duration", type=float, default=None,
                        help="seconds to run (default: 14 s for press, 12 s for tear and cut; offline: the "
                             "script's 4.85 s)")
    parser.add_argument("--mesh", type=Path, default=None, metavar="PATH",
                        help="run on this volume mesh (.msh .vtu .vtk .mesh) or closed surface (.stl .obj .ply "
                             ".off) instead of the default liver; the simulated hand presses its top")
    add_scale_argument(parser)
    parser.add_argument("--out", type=Path, default=Path("out/demo"), help="output folder (default: %(default)s)")
    parser.add_argument("--offline", action="store_true", help="scripted press-and-release in this process, no ROS")
    parser.add_argument("--record", action="store_true", help="record the run with `liver-sim record` into OUT/session")
    parser.add_argument("--storage", choices=STORAGES, default="mcap", help="storage of the recorded bag")
    add_link_arguments(parser)
    parser.add_argument("--view", action="store_true", help="serve the live view (`liver-sim view`) beside the nodes "
                        "and draw OUT/view.png")
    parser.add_argument("--view-port", type=int, default=None, metavar="P", help="the live view's port (default "
                        "8765; 0: any free one)")
    parser.add_argument("--tools", type=int, choices=(1, 2), default=1,
                        help="2: two hands on the default liver, two simulated PHANToMs in /left and /right (the left "
                             "grasps and lifts the edge, the right presses and cuts beside it)")
    parser.set_defaults(handler=demo)


def add_link_arguments(parser) -> None:
    """--link-delay, --link-jitter, --link-loss, --link-seed: the emulated teleoperation link
    (liver_sim.base.emulated_link)."""
    parser.add_argument("--link-delay", type=float, default=0.0, metavar="S",
                        help="one-way delay (s) between the operator's side (device, tool, bridge) and the physics, "
                             "both ways (default: 0, no link)")
    parser.add_argument("--link-jitter", type=float, default=0.0, metavar="S",
                        help="jitter (s): each message's delay is the delay ± up to this; order is kept")
    parser.add_argument("--link-loss", type=float, default=0.0, metavar="F", help="fraction of messages lost (0-1)")
    parser.add_argument("--link-seed", type=int, default=0, help="seed of the jitter and loss")


def link_settings(args):
    """The LinkSettings of --link-*, checked against the nodes' parameter ranges (ValueError naming the option)."""
    settings = LinkSettings(args.link_delay, args.link_jitter, args.link_loss, args.link_seed)
    for (name, value), option in zip(settings.parameters().items(), ("delay", "jitter", "loss", "seed")):
        try:
            check_parameter(name, LINK_PARAMETERS[name], value)
        except ValueError as exc:
            raise ValueError(f"--link-{option}: {exc}") from None
    return settings


def demo(args) -> int:
    # this command's own modules, loaded when it runs (module docstring)
    from liver_sim.studies.demo import run_demo
    from liver_sim.studies.demo_liver import DemoMesh
    from liver_sim.studies.demo_offline import run_offline_demo
    from liver_sim.studies.two_hands import run_two_hands

    progress = lambda line: print(line, flush=True)  # noqa: E731
    if args.mesh is None and args.scale != 1.0:
        raise ValueError("--scale applies to --mesh PATH; the default liver is in metres")
    link = link_settings(args)  # refused before the liver is built
    if args.offline and (args.record or args.view or args.scenario != "press" or link.emulated or args.tools != 1):
        raise ValueError("--record, --view, --scenario, --tools and --link-* run the node network; --offline is the "
                         "press without ROS")
    if args.tools == 2 and (args.scenario != "press" or args.mesh is not None or link.emulated):
        raise ValueError("--tools 2 runs its own scene (two hands) on the default liver, without a link: "
                         "--scenario, --mesh and --link-* take one tool")
    liver = DemoMesh(args.mesh, args.scale)
    view = (["--port", str(args.view_port)] if args.view_port is not None else []) if args.view else None
    record_storage = args.storage if args.record else None
    if args.offline:
        run_offline_demo(args.out, args.duration, progress, liver)
    elif args.tools == 2:
        run_two_hands(args.out, args.duration, progress, record_storage, view)
    else:
        run_demo(args.out, args.duration, progress, record_storage=record_storage, scenario=args.scenario,
                 liver=liver, link=link, view=view)
    return 0


def add_view_command(commands) -> None:
    """``liver-sim view [--host H] [--port P] [--rate HZ] [--allow-remote] [--picture PNG] [--duration S]
    [--summary JSON] [--tools NAME …]``."""
    parser = commands.add_parser("view", help="serve the running network to the Foxglove app (a WebSocket on "
                                              f"{DEFAULT_HOST}:{DEFAULT_PORT}): the deforming liver, tool, local "
                                              "model, forces and diagnostics")
    parser.add_argument("--host", default=DEFAULT_HOST, help="address to serve on (default: %(default)s)")
    parser.add_argument("--port", type=int, default=DEFAULT_PORT, help="port (default: %(default)s; 0: any free one)")
    parser.add_argument("--rate", type=float, default=VIEW_RATE_HZ, help="scenes per second (default: %(default)s)")
    parser.add_argument("--allow-remote", action="store_true",
                        help="allow a --host that is not a loopback address (the view has no authentication)")
    parser.add_argument("--picture", type=Path, default=None, metavar="PNG",
                        help="at exit, draw the scene with the largest contact force into this PNG")
    parser.add_argument("--duration", type=float, default=None, help="seconds to serve (default: until Ctrl-C)")
    parser.add_argument("--summary", type=Path, default=None, metavar="JSON",
                        help="at exit, write what was served into this JSON file (scenes, seconds, scenes_per_s, "
                             "refused_messages, tick_errors)")
    add_tools_argument(parser, "show")
    parser.set_defaults(handler=view)


def view(args) -> int:
    # this command's own modules, loaded when it runs (module docstring)
    from liver_sim.view.server import serve

    if not 1.0 <= args.rate <= 150.0:
        raise ValueError(f"--rate must lie in [1, 150] scenes per second, got {args.rate:g}")
    if not 0 <= args.port <= 65535:
        raise ValueError(f"--port must lie in [0, 65535], got {args.port}")
    serve(args.host, args.port, args.rate, args.allow_remote, args.picture, args.duration,
          lambda line: print(line, flush=True), args.summary, args.tools)
    return 0


#: The subcommands, in the order `liver-sim --help` lists them.
COMMANDS = (add_mesh_command, add_traction_command, add_validate_command, add_bench_command, add_demo_command,
            add_record_command, add_replay_command, add_resimulate_command, add_fig8_command, add_report_command,
            add_bag_command, add_view_command, add_warm_command)


def build_parser() -> argparse.ArgumentParser:
    """The ``liver-sim`` argument parser with every subcommand in :data:`COMMANDS`."""
    parser = argparse.ArgumentParser(prog=PROG, description="Human liver simulation "
                                     "(Boux de Casson et al.): meshes, traction tests, demos.")
    parser.add_argument("--discovery-range", choices=DISCOVERY_RANGES, default=None,
                        help="DDS discovery range of the commands that start ROS (default: "
                             "$ROS_AUTOMATIC_DISCOVERY_RANGE if set, else LOCALHOST: nothing leaves this machine)")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for add_command in COMMANDS:
        add_command(commands)
    return parser


def starts_ros(args) -> bool:
    """Whether the parsed command starts ROS (a context or node processes)."""
    return (args.command in ("record", "replay", "view") or (args.command == "demo" and not args.offline)
            or (args.command == "bench" and args.bench in ("loop", "record", "teleop", "floor")))


def _terminate(signum, _frame) -> None:
    """SIGTERM/SIGHUP end a command like Ctrl-C does: cleanup (stopping started nodes) runs."""
    raise SystemExit(128 + signum)


def main(argv=None) -> int:
    """Run ``liver-sim`` with `argv` (default: sys.argv[1:]); return the exit status."""
    for signum in (signal.SIGTERM, signal.SIGHUP):
        signal.signal(signum, _terminate)
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help or a usage error, already reported by argparse
        return exc.code if isinstance(exc.code, int) else EXIT_REFUSED
    try:
        if starts_ros(args):
            # stdout, beside the command's progress; stderr when stdout carries JSON
            print(f"{PROG}: {keep_dds_local(args.discovery_range)}; {use_dds_profile()}", flush=True,
                  file=sys.stderr if getattr(args, "json", False) else sys.stdout)
        return args.handler(args)
    except ValueError as exc:  # MeshError, or a refusal of the stuffing; both name the source
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return EXIT_REFUSED
    except NodeFailure as exc:  # names the node, its status and the end of its log
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return EXIT_NODE_FAILED
    except DomainOccupied as exc:  # names what already runs on the domain
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return EXIT_REFUSED


if __name__ == "__main__":
    sys.exit(main())
