"""The job's plan: its pairs held as columns, its tasks cut from them, and its JSON round trip.

A plan of the whole Bandai Namco dataset holds 3.1 M pairs, so the plan keeps them as int32
columns (:class:`~torchsplice.job.pairs.PairTable`) and cuts them into tasks by array
operations; these tests hold those against the plain Python of one :class:`Pair` at a time.
"""

from __future__ import annotations

import json
import random

import pytest

from torchsplice.core.errors import UnfinishedJobError
from torchsplice.job.config import job_config
from torchsplice.job.pairs import MODES, Pair, PairTable
from torchsplice.job.plan import Plan, _padded_chunks, make_plan
from torchsplice.job.sources import Sources


def _random_pairs(n: int, seed: int) -> list[Pair]:
    rng = random.Random(seed)
    return [Pair(rng.choice(["splice", "naive", "cpmc"]), rng.randrange(5000), rng.randrange(5000),
                 rng.choice([None, rng.randrange(5000)]), rng.choice(MODES), rng.choice([None, 0, 3]))
            for _ in range(n)]


def test_a_pair_table_gives_back_the_pairs_it_was_made_of():
    pairs = _random_pairs(1000, 0)
    table = PairTable.from_pairs(pairs, methods=["splice", "naive", "cpmc"])
    assert len(table) == 1000 and list(table) == pairs and table[17:300] == pairs[17:300]
    assert table[-1] == pairs[-1] and table[5] == pairs[5]
    assert table.count("standing") == sum(p.mode == "standing" for p in pairs)
    with pytest.raises(IndexError):
        table[1000]


def test_a_pair_tables_json_round_trip_is_exact():
    table = PairTable.from_pairs(_random_pairs(777, 1))
    again = PairTable.from_dict(json.loads(json.dumps(table.to_dict())))
    assert again == table and list(again) == list(table)
    assert PairTable.from_dict(PairTable.from_pairs([]).to_dict()) == PairTable.from_pairs([])


@pytest.mark.parametrize("damage", ["short", "not base64", "not an object"])
def test_a_plan_with_damaged_pair_columns_is_one_line(sample_db, tmp_path, damage):
    plan = make_plan(job_config(sample_db, tmp_path / "out.h5"), Sources(sample_db))
    d = json.loads(plan.to_json())
    if damage == "short":
        d["pairs"]["loco"] = d["pairs"]["loco"][:-8]
    elif damage == "not base64":
        d["pairs"]["action"] = "%%%%"
    else:
        d["pairs"] = [[1, 2, 3]]
    path = tmp_path / "plan.json"
    path.write_text(json.dumps(d))
    with pytest.raises(UnfinishedJobError) as err:
        Plan.load(path)
    assert str(path) in str(err.value) and "not a readable job plan" in str(err.value)
    assert "\n" not in str(err.value)


def _tasks_one_pair_at_a_time(plan: Plan) -> list[tuple]:
    """The tasks as the plan cut them before its pairs were columns: one pair at a time, a new
    task where the method, locomotion group or mode changes or the task is full."""
    tl = Sources(plan.key["database"]["path"]).db("L").clip_table()
    group_of = {(g.skeleton, g.fps): n for n, g in enumerate(plan.groups)}
    pairs, size, out, start = list(plan.pairs), plan.key["task_pairs"], [], 0

    def group(p):
        return group_of[(int(tl.skeleton[p.loco]), float(tl.fps[p.loco]))]

    for n in range(1, len(pairs) + 1):
        p0 = pairs[start]
        if n == len(pairs) or n - start >= size or (pairs[n].method, group(pairs[n]), pairs[n].mode) != (
                p0.method, group(p0), p0.mode):
            out.append((f"{len(out):06d}", p0.method, group(p0), start, n, p0.mode))
            start = n
    return out


@pytest.mark.parametrize("options", [dict(batch_pairs=7, methods="splice,naive,cpmc"), dict(batch_pairs=1),
                                     dict(methods="naive,splice")])
def test_the_plans_tasks_are_cut_as_one_pair_at_a_time_would_cut_them(sample_db, tmp_path, options):
    plan = make_plan(job_config(sample_db, tmp_path / "out.h5", **options), Sources(sample_db))
    got = [(t.id, t.method, t.group, t.start, t.stop, t.mode) for t in plan.tasks]
    assert got == _tasks_one_pair_at_a_time(plan)
    assert plan.tasks[0].start == 0 and plan.tasks[-1].stop == len(plan.pairs)
    again = Plan.from_json(plan.to_json())
    assert again.pairs == plan.pairs and again.digest() == plan.digest()
    for t in plan.tasks:  # every pair of a task is of its method and mode
        assert {(p.method, p.mode) for p in plan.pairs[t.start:t.stop]} == {(t.method, t.mode)}


def test_padded_chunks_keep_the_order_and_bound_each_padded_batch():
    rng = random.Random(2)
    frames = sorted(rng.choice([30, 120, 900, 4000, 70_000]) for _ in range(2000))
    keys = [f"L:{n}" for n in range(len(frames))]
    chunks = _padded_chunks(keys, frames, budget=65_536, most=256)
    assert [k for c in chunks for k in c] == keys
    length = dict(zip(keys, frames))
    for c in chunks:
        assert len(c) <= 256
        assert len(c) == 1 or len(c) * max(length[k] for k in c) <= 65_536
    # each chunk is as full as the bounds allow: the next clip would break one of them
    for c, nxt in zip(chunks, chunks[1:]):
        assert len(c) == 256 or (len(c) + 1) * max(length[k] for k in c + nxt[:1]) > 65_536
