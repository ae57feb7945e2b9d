"""`gymnast collect` through the rollout engine writes, byte for byte, the dataset it wrote before.

collect_sha256_before_engine.json holds the SHA-256 of every file two collections wrote when
collect still stepped its episodes by hand (commit af35195): scripted experts, noisy experts and
failures in the real world, and experts in the mild simulator, all with one worker (with several,
episodes are stored in completion order). The videos' bytes are those of the encoder the hashes
were recorded with (PyAV 18.1.0's FFmpeg); another build encodes the same frames into other bytes,
so there only the videos' names are held to the record, and every other file's bytes still are.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import av
import pytest

from gymnast.config import EnvConfig
from gymnast.data.collect import CollectConfig, collect

BEFORE = json.loads((Path(__file__).parent / "collect_sha256_before_engine.json").read_text())
ENV = EnvConfig(image_size=32, horizon=30)
RECORDED_WITH_AV = "18.1.0"


@pytest.mark.slow
def test_collect_writes_the_same_bytes_as_before_the_rollout_engine(tmp_path: Path):
    collect(CollectConfig(tasks="reach-v3,drawer-open-v3", episodes_per_task=3, workers=1, env=ENV),
            tmp_path / "data", progress=False)
    collect(CollectConfig(tasks="push-v3", episodes_per_task=2, gap="mild", workers=1, env=ENV),
            tmp_path / "data_mild", progress=False)
    written = {str(path.relative_to(tmp_path)): hashlib.sha256(path.read_bytes()).hexdigest()
               for path in sorted(tmp_path.rglob("*")) if path.is_file()}
    if av.__version__ == RECORDED_WITH_AV:
        assert written == BEFORE
        return
    assert written.keys() == BEFORE.keys()
    assert {name: digest for name, digest in written.items() if not name.endswith(".mp4")} == \
        {name: digest for name, digest in BEFORE.items() if not name.endswith(".mp4")}
