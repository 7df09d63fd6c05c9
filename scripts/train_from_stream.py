"""Train a small text-to-motion model for a few steps on spliced clips streamed from an alignment
store: no per-clip files, HumanML3D's 263 features and captions, splits by source clip, and a
checkpoint that resumes mid-epoch with the same batches.

    python scripts/train_from_stream.py                    # the built-in sample, spliced here
    python scripts/train_from_stream.py spliced.h5 --steps 200 --workers 2

Without a database it splices the built-in sample into an alignment store in a temporary
folder first. The model is deliberately tiny (a bag-of-words text encoder and a GRU decoder of
the features); it shows the data path, not a method.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import torch
from torch import nn
from torch.utils.data import DataLoader

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from torchsplice.formats.humanml3d_stream import HumanML3DStream  # noqa: E402


class TinyTextToMotion(nn.Module):
    """Words hashed into a bag-of-words embedding, a GRU unrolled to the motion's length."""

    def __init__(self, dim: int = 263, hidden: int = 128, vocab: int = 4096):
        super().__init__()
        self.vocab = vocab
        self.words = nn.EmbeddingBag(vocab, hidden)
        self.gru = nn.GRU(hidden, hidden, batch_first=True)
        self.out = nn.Linear(hidden, dim)

    def forward(self, captions: list[str], frames: int) -> torch.Tensor:
        ids, offsets = [], []
        for c in captions:
            offsets.append(len(ids))
            ids += [hash(w) % self.vocab for w in c.lower().split()] or [0]
        text = self.words(torch.tensor(ids), torch.tensor(offsets))  # (B, hidden)
        steps = text[:, None, :].expand(-1, frames, -1).contiguous()
        hidden, _ = self.gru(steps, text[None].contiguous())
        return self.out(hidden)


def train(database: Path, steps: int, workers: int, batch_size: int, checkpoint: Path | None) -> float:
    stream = HumanML3DStream(database, batch_size=batch_size, split=None, seed=0)
    mean, std = stream.statistics
    stream.normalize = (torch.from_numpy(mean), torch.from_numpy(std.clip(min=1e-6)))
    model = TinyTextToMotion()
    opt = torch.optim.Adam(model.parameters(), lr=1e-3)
    if checkpoint is not None and checkpoint.exists():
        saved = torch.load(checkpoint)
        model.load_state_dict(saved["model"])
        opt.load_state_dict(saved["optimizer"])
        stream.load_state_dict(saved["stream"])
        print(f"resumed at epoch {saved['stream']['epoch']}, batch {saved['stream']['next_batch']}")
    loss = float("nan")
    done = 0
    while done < steps:
        for batch in DataLoader(stream, batch_size=None, num_workers=workers):
            pred = model(batch["caption"], batch["motion"].shape[1])
            mask = batch["mask"][..., None].float()
            loss_t = (((pred - batch["motion"]) ** 2) * mask).sum() / (mask.sum() * pred.shape[-1])
            opt.zero_grad()
            loss_t.backward()
            opt.step()
            loss, done = float(loss_t.detach()), done + 1
            if checkpoint is not None:
                torch.save({"model": model.state_dict(), "optimizer": opt.state_dict(),
                            "stream": stream.state_at(batch)}, checkpoint)
            print(f"step {done}: epoch {batch['epoch']} batch {batch['batch']} loss {loss:.4f}")
            if done >= steps:
                break
        else:
            stream.set_epoch(stream.epoch + 1)
    return loss


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("database", nargs="?", help="an alignment (or motion) store; default: splice the built-in sample")
    p.add_argument("--steps", type=int, default=20)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--batch-size", type=int, default=16)
    p.add_argument("--checkpoint", type=Path, default=None, help="save after every step; resume from it if present")
    args = p.parse_args(argv)
    torch.manual_seed(0)
    if args.database is not None:
        train(Path(args.database), args.steps, args.workers, args.batch_size, args.checkpoint)
        return 0
    from torchsplice.cli import main as torchsplice
    from torchsplice.job import splice_all

    with tempfile.TemporaryDirectory() as tmp:
        sample, out = Path(tmp) / "sample.h5", Path(tmp) / "spliced.h5"
        torchsplice(["sample", "-o", str(sample), "-q"])
        splice_all(sample, out, store="alignment", methods="splice,naive", workers=1, index=False)
        train(out, args.steps, args.workers, args.batch_size, args.checkpoint)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
