"""``export``: clips of a database as files of a registered format (BVH, .npz, or a plug-in's).

The command parses its flags and calls :func:`torchsplice.formats.exporters.export_clips`, which
does everything else (the format, the files, all or nothing), exactly as from Python. The
formats (``--format``) are the registry's, so a ``--plugin`` module's format is a choice too;
``--packed`` and ``--features`` are the ``npz`` format's options, with its default and choices.
"""

from __future__ import annotations

from .base import Command, register_command
from .common import add_output_flags, command_line, progress, say
from ..core.errors import TorchspliceError
from ..formats.defaults import DEFAULT_EXPORT_INDEX


def _option(format: str, name: str):
    from ..formats.exporters import get_exporter

    return get_exporter(format).options[name]


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
        from ..formats.exporters import DEFAULT_FORMAT, available_exporters

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
        packed, features = _option("npz", "packed"), _option("npz", "features")
        s.add_argument("--packed", action="store_true", default=packed.default,
                       help="npz: one file with every clip concatenated along frames and offsets[i]:offsets[i+1] "
                            "slicing clip i (clips of one skeleton topology)")
        s.add_argument("--features", choices=features.choices, default=features.default,
                       help="npz: add 6D rotations (Zhou et al. 2019), joint, root and trajectory velocities, and per-"
                            "dimension mean and std of every array over all exported clips, for normalisation")
        h = {k: _option("humanml3d", k).default for k in ("mirror", "split_ratios", "split_seed", "paraphrases")}
        s.add_argument("--captions", default=None, metavar="FILE",
                       help="humanml3d: your captions per source clip (JSON: clip name -> list of captions, each "
                            "'caption#word/POS ...#0.0#0.0' or word/POS words); they compose like the labels' phrases")
        s.add_argument("--mirror", action="store_true", default=None,
                       help=f"humanml3d: add each clip's mirrored copy (M + ID), left and right swapped in the motion and "
                            f"its captions (default: {'on' if h['mirror'] else 'off'}); for the other formats, write "
                            "the mirror images with `torchsplice mirror` and export that database")
        s.add_argument("--window", type=float, default=None, metavar="SECONDS",
                       help="humanml3d: cut clips longer than SECONDS into windows of SECONDS spread over the clip, "
                            "each with the clip's captions (MDM and MoMask keep motions of 40 to 199 frames: windows of at most 9.95 s, at least 2.05 s)")
        s.add_argument("--split-ratios", default=None, metavar="TRAIN,VAL,TEST",
                       help="fractions of the source clips in each split of the index (every format) or the "
                            "HumanML3D lists; a result is in a split when all its sources are "
                            f"(default: {','.join(f'{r:g}' for r in h['split_ratios'])})")
        s.add_argument("--split-seed", type=int, default=None, metavar="N",
                       help=f"the seed of the split (default: {h['split_seed']})")
        s.add_argument("--no-index", dest="index", action="store_false", default=DEFAULT_EXPORT_INDEX,
                       help="several clips: write no index.csv (each file's clip, split, role, labels, cost, flags, "
                            "coverage...) and no train/val/test.txt beside them")
        s.add_argument("--paraphrases", type=int, default=None, metavar="N",
                       help=f"humanml3d: captions per clip, at most (default: {h['paraphrases']})")
        s.add_argument("--shards", type=int, default=None, metavar="N",
                       help="humanml3d: write the motions as about N tar files in WebDataset's layout (ID.npy, ID.txt; "
                            "SPLIT-000000.tar ...) instead of one file each")
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
                              overwrite=args.force, skeletons=skeletons, command=command_line(args),
                              packed=args.packed, features=args.features, captions=args.captions, mirror=args.mirror,
                              window=args.window, split_ratios=args.split_ratios, split_seed=args.split_seed,
                              paraphrases=args.paraphrases, shards=args.shards, index=args.index,
                              progress=lambda it, total, desc: progress(it, total, desc, args.quiet))
        say(args, f"wrote {result.summary}")
        return 0


register_command(Export())
