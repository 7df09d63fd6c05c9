"""``export``: clips of a database as files of a registered format (BVH, .npz, or a plug-in's).

The command parses its flags and calls :func:`torchsplice.formats.exporters.export_clips`, which
does everything else (the format, the files, all or nothing), exactly as from Python. The
formats (``--format``) are the registry's, so a ``--plugin`` module's format is a choice too;
so are the formats' options: each option a registered format declares
(:attr:`~torchsplice.formats.exporters.Exporter.options`, an
:class:`~torchsplice.formats.defaults.ExportOption` each) is a flag (:func:`add_format_flags`:
``--packed`` and ``--features`` are the ``npz`` format's, ``--mirror`` ... ``humanml3d``'s, a
plug-in's its own), with its type, choices and help.
"""

from __future__ import annotations

import argparse

from .base import Command, register_command
from .common import add_output_flags, command_line, flag, progress, say
from ..core.errors import TorchspliceError, render_message
from ..formats.defaults import DEFAULT_EXPORT_INDEX, DEFAULT_FORMAT


def format_options() -> dict:
    """Every registered format's options: name -> (its declaration, the formats that take it),
    in registration order (the first format's declaration of a name is the flag's)."""
    from ..formats.exporters import available_exporters, get_exporter

    out: dict = {}
    for format in available_exporters():
        for name, option in get_exporter(format).options.items():
            out.setdefault(name, (option, []))[1].append(format)
    return out


def add_format_flags(s, later: tuple[str, ...] = ()) -> tuple[str, ...]:
    """A flag for each format's option (:func:`format_options`): ``--NAME`` (a switch for one
    that is off or on by default), its help after the formats that take it (``npz: ...``; none
    for an option every export takes, :data:`~torchsplice.formats.exporters.SHARED_OPTIONS`).
    Its default is ``None``: the format's own. An option whose flag or name the command has
    already (or adds ``later``: flags and names) is left to Python. Returns the options that got a flag."""
    from ..formats.exporters import SHARED_OPTIONS

    taken = {d for a in s._actions for d in (a.dest, *a.option_strings)} | {"format_options", *later}
    added = []
    for name, (option, formats) in format_options().items():
        if flag(name) in taken or name in taken:
            continue
        text = (option.help or f"the {name} option").replace("%", "%%")  # argparse formats help with %
        kwargs = dict(dest=name, default=None, help=text if name in SHARED_OPTIONS else f"{', '.join(formats)}: {text}")
        if isinstance(option.default, bool):
            kwargs["action"] = argparse.BooleanOptionalAction if option.default else "store_true"
        else:
            kwargs.update(type=option.type, choices=option.choices, metavar=option.metavar)
        s.add_argument(flag(name), **kwargs)
        added.append(name)
    s.set_defaults(format_options=tuple(added))
    return tuple(added)


class Export(Command):
    name = "export"
    help = "write clips of a database as BVH, NumPy .npz or a HumanML3D folder (for training and other tools)"
    description = ("Write clips (by name, as `info` lists them, or --all) as BVH files with the skeleton's original "
                   "channel layout, or as .npz: local rotations (WXYZ), root translation, trajectory, local "
                   "translations, world positions, fps, joints, parents, offsets and labels (layout: "
                   "torchsplice/formats/npz.py), or as a HumanML3D folder for text-to-motion training (--format "
                   "humanml3d: the SMPL body's 263 features at 20 fps, captions from the labels, Mean/Std, splits by "
                   "source clip, index.csv; layout: torchsplice/formats/humanml3d_exporter.py). -o is a file for one "
                   "clip (or --packed), else a folder, one file per clip.")

    def add_arguments(self, s) -> None:
        from ..formats.exporters import available_exporters

        formats = available_exporters()
        s.add_argument("database", help="motion database (.h5)")
        s.add_argument("clips", nargs="*", metavar="CLIP",
                       help="clip names, or selectors of the selection language ('role:spliced', 'method:naive', "
                            "'label:action.style=old', 'walk_*'), any of which selects a clip")
        s.add_argument("-o", "--output", required=True, help="file to write (one clip, --packed), or folder (several clips)")
        s.add_argument("--all", action="store_true", help="export every clip (or every clip of --skeleton)")
        s.add_argument("--format", choices=formats, default=None,
                       help=f"{' or '.join(formats) if len(formats) < 3 else ', '.join(formats)} (default: from -o's "
                            f"suffix; {DEFAULT_FORMAT} for a folder unless --packed or --features)")
        add_format_flags(s, later=("--no-index", "index", "--select", "select", "--skeleton", "skeleton", "-f", "--force",
                                   "force", "-q", "--quiet", "quiet"))
        s.add_argument("--no-index", dest="index", action="store_false", default=DEFAULT_EXPORT_INDEX,
                       help="several clips: write no index.csv (each file's clip, split, role, labels, cost, flags, "
                            "coverage...) and no train/val/test.txt beside them")
        s.add_argument("--select", action="append", metavar="SELECT", default=None,
                       help="only clips this selector selects (repeat: all of them), as splice-all's --locomotions read")
        s.add_argument("--skeleton", default=None, metavar="K[,K...]",
                       help="only clips on these skeletons (ids as `info` lists them)")
        add_output_flags(s)

    def run(self, args) -> int:
        from ..formats.exporters import export_clips

        if args.all and args.clips:
            raise TorchspliceError("name the clips to export, or pass --all (not both)")
        if not (args.all or args.clips or args.select):  # --select alone: the clips it selects, as retarget takes it
            raise TorchspliceError("name the clips to export (as `torchsplice info` lists them), or pass --all or --select")
        skeletons = None
        if args.skeleton is not None:
            try:
                skeletons = sorted({int(k) for k in args.skeleton.split(",") if k.strip()})
            except ValueError:
                raise TorchspliceError(f"--skeleton: expected skeleton ids such as 0 or 0,1, got {args.skeleton!r}") from None
        clips, select = None, list(args.select or [])
        if args.clips:
            from ..store.database import MotionDatabase
            from ..store.select import names_or_selector

            with MotionDatabase.open(args.database) as db:
                clips, chosen = names_or_selector(db.clip_table(), args.clips)
            select += [chosen] if chosen else []
        result = export_clips(args.database, clips, out=args.output, format=args.format, select=select or None,
                              overwrite=args.force, skeletons=skeletons, command=command_line(args), index=args.index,
                              **{name: getattr(args, name) for name in args.format_options},
                              progress=lambda it, total, desc: progress(it, total, desc, args.quiet))
        say(args, f"wrote {render_message(result.summary_text, result.summary_options, flag)}")
        return 0


register_command(Export())
