from pathlib import Path

import pytest

from physmotion.data.stats import dataset_stats

pytestmark = pytest.mark.slow


def test_stats_count_what_the_build_wrote(built_dir: Path, built) -> None:
    stats = dataset_stats(built_dir)
    assert stats.items == built.num_items
    # minutes count every item (mirrored copies, frames held at a short clip's ends), as minutes_with_mirrors
    assert stats.total_minutes == pytest.approx(built.minutes_with_mirrors, rel=1e-6)
    assert built.minutes_with_mirrors >= 2 * built.minutes  # the build's minutes of capture leave both out
    assert stats.vocabulary["walk"] > 0 and stats.vocabulary["person"] > 0
    assert stats.licences.keys() == {"NC", "open"}
    assert stats.captions >= sum(stats.items.values())
