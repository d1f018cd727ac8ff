"""Which photo pairs prepare matches: the matcher by count and order, the pairs each one makes,
and whether a set of photos follows a walk (known answers on a real video's frames)."""

from __future__ import annotations

import numpy as np
import pytest

from windowshop.photos import pairs
from shared_data import DATA


def _walk(count: int, dims: int = 64, seed: int = 0) -> np.ndarray:
    """(count, dims) unit descriptors drifting slowly: each is its predecessor plus a little."""
    rng = np.random.default_rng(seed)
    steps = np.cumsum(rng.normal(size=(count, dims)), axis=0)
    return steps / np.linalg.norm(steps, axis=1, keepdims=True)


def test_small_sets_match_every_pair():
    assert pairs.choose(pairs.EXHAUSTIVE_MAX, None) == "exhaustive"
    assert len(pairs.image_pairs(10, "exhaustive")) == 45


def test_large_ordered_sets_match_in_sequence_and_shuffled_ones_by_retrieval():
    walk = _walk(60)
    assert pairs.choose(60, walk) == "sequential"
    shuffled = walk[np.random.default_rng(1).permutation(60)]
    assert not pairs.is_walk(shuffled)
    assert pairs.choose(60, shuffled) == "retrieval"


def test_sequential_pairs_join_each_photo_with_its_next_few():
    got = pairs.image_pairs(8, "sequential")
    assert all(0 < j - i <= pairs.SEQUENTIAL_OVERLAP for i, j in got)
    assert len(got) == sum(min(pairs.SEQUENTIAL_OVERLAP, 7 - i) for i in range(8))


def test_retrieval_pairs_find_a_shuffled_walks_neighbours():
    """Retrieval on a shuffled walk pairs (nearly) every photo with its true neighbour in the
    walk, with far fewer pairs than exhaustive matching."""
    count = 100
    walk = _walk(count)
    order = np.random.default_rng(2).permutation(count)
    got = set(pairs.image_pairs(count, "retrieval", walk[order]))
    position = np.argsort(order)  # walk index -> shuffled index
    neighbours = {tuple(sorted((int(position[i]), int(position[i + 1]))))
                  for i in range(count - 1)}
    assert len(neighbours & got) >= 0.95 * len(neighbours)
    assert len(got) <= count * (pairs.RETRIEVAL_K + pairs.SEQUENTIAL_OVERLAP) < count * (count - 1) / 2


def test_photos_turned_by_quarters_keep_their_neighbours_in_file_order(tmp_path):
    """fruit's photos turned 0/90/180/270 degrees in turn (EXIF orientation lost) are no walk to
    their thumbnails, and retrieval by thumbnail alone pairs few of them with their next photo;
    retrieval's pairs still hold each photo's next few in file order."""
    from PIL import Image

    images = sorted((DATA / "fruit" / "newfruit_small").glob("*.jpg"))[:48]
    if not images:
        pytest.skip("fruit is not in the shared data")
    turned = []
    for k, path in enumerate(images):
        with Image.open(path) as image:
            out = tmp_path / path.name
            image.rotate(90 * (k % 4), expand=True).save(out)
            turned.append(out)
    descriptors = pairs.tiny_descriptors(turned)
    assert pairs.choose(len(turned), descriptors) == "retrieval"
    alike = pairs._most_alike(descriptors, pairs.RETRIEVAL_K)
    by_thumbnail = sum(k + 1 in alike[k] or k in alike[k + 1] for k in range(len(turned) - 1))
    assert by_thumbnail < 0.7 * (len(turned) - 1)
    got = set(pairs.image_pairs(len(turned), "retrieval", descriptors))
    assert all((k, j) in got for k in range(len(turned))
               for j in range(k + 1, min(k + 1 + pairs.SEQUENTIAL_OVERLAP, len(turned))))


def test_video_frames_in_order_are_a_walk():
    """beer_can's 71 frames (a walk around a can) in file order are a walk; shuffled, not."""
    images = sorted((DATA / "beer_can" / "images").glob("*.jpg"))
    if not images:
        pytest.skip("beer_can is not in the shared data")
    descriptors = pairs.tiny_descriptors(images)
    assert descriptors.shape == (len(images), pairs.THUMB**2)
    assert pairs.is_walk(descriptors)
    assert not pairs.is_walk(descriptors[np.random.default_rng(0).permutation(len(images))])
