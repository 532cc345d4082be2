"""The matching rules of the ``flow`` association on hand-made sequences, and the order in
which it visits the views. The images are uniform, so the optical flow is zero and the rules
alone decide; the cameras stand on a line in the order of the list."""

import numpy as np

from dataset_tools.cameras import CameraPose, PinholeCamera
from hqmask.association.flow import associate_flow, pose_order


def on_a_line(n: int, shape: tuple[int, int]) -> list[CameraPose]:
    """Telephoto cameras one unit apart along x, all looking along +z: every ray is parallel
    to every other within a degree, so the poses say nothing and the rules alone decide."""
    camera = PinholeCamera(shape[1], shape[0], 1e5, 1e5, shape[1] / 2, shape[0] / 2)
    return [CameraPose(camera, np.concatenate([np.eye(3), [[-k], [0.0], [0.0]]], 1)) for k in range(n)]


def associate_flow_on_a_line(images: list[np.ndarray], segments: list[np.ndarray]) -> list[np.ndarray]:
    return associate_flow(images, segments, on_a_line(len(images), segments[0].shape))


def associate(segments: list[np.ndarray]) -> list[np.ndarray]:
    images = [np.full((*s.shape, 3), 128, np.uint8) for s in segments]
    return associate_flow_on_a_line(images, segments)


def box(shape: tuple[int, int], boxes: dict[int, tuple[int, int, int, int]]) -> np.ndarray:
    seg = np.zeros(shape, np.int32)
    for label, (y0, y1, x0, x1) in boxes.items():
        seg[y0:y1, x0:x1] = label
    return seg


def test_an_object_moving_further_than_the_flow_carries_it_keeps_its_id():
    """Each step moves the box 12 of its 20 px: consecutive masks overlap with IoU 0.25, under
    the first round's 0.3; the second round keeps the track."""
    segments = [box((40, 200), {1: (10, 30, 10 + 12 * k, 30 + 12 * k)}) for k in range(6)]
    ids = {int(i) for out, seg in zip(associate(segments), segments) for i in np.unique(out[seg > 0])}
    assert ids == {1}


def test_a_mask_split_in_one_view_gets_one_id():
    segments = [box((40, 60), {1: (10, 30, 10, 50)}) for _ in range(5)]
    segments[2] = box((40, 60), {1: (10, 30, 10, 30), 2: (10, 30, 30, 50)})
    out = associate(segments)
    assert all(set(np.unique(o[s > 0])) == {1} for o, s in zip(out, segments))


def test_two_objects_one_mask_merged_in_the_first_view_stay_apart_after_it():
    """View 0 has one segment over two touching boxes; views 1..5 have one segment each."""
    left, right = (10, 30, 10, 30), (10, 30, 30, 50)
    segments = [box((40, 60), {1: (10, 30, 10, 50)})] + [box((40, 60), {1: left, 2: right}) for _ in range(5)]
    out = associate(segments)
    for o in out[1:]:
        a, b = o[15, 15], o[15, 45]
        assert a > 0 and b > 0 and a != b
    assert len({(o[15, 15], o[15, 45]) for o in out[1:]}) == 1  # the same two IDs in every view


def test_a_mask_split_in_two_separate_views_gets_one_id():
    """Split in views 2 and 5: the pieces meet again, yet the views that show them as one
    object (a segment holding both) outnumber those that show them apart."""
    segments = [box((40, 60), {1: (10, 30, 10, 50)}) for _ in range(8)]
    for k in (2, 5):
        segments[k] = box((40, 60), {1: (10, 30, 10, 30), 2: (10, 30, 30, 50)})
    out = associate(segments)
    assert all(set(np.unique(o[s > 0])) == {1} for o, s in zip(out, segments))


def test_a_lost_object_is_reidentified_by_its_colours():
    """A red box is missed in views 3 and 4 and seen again far from where its mask was carried;
    a blue box appearing at the same place and time is another object."""
    def view(boxes: dict[int, tuple[tuple[int, int, int, int], tuple[int, int, int]]]):
        seg, image = np.zeros((40, 200), np.int32), np.full((40, 200, 3), 128, np.uint8)
        for label, ((y0, y1, x0, x1), color) in boxes.items():
            seg[y0:y1, x0:x1], image[y0:y1, x0:x1] = label, color
        return image, seg

    red, blue = (200, 30, 30), (30, 30, 200)
    for color, same in ((red, True), (blue, False)):
        views = ([view({1: ((10, 30, 10, 30), red)}) for _ in range(3)] + [view({}) for _ in range(2)]
                 + [view({1: ((10, 30, 150, 170), color)}) for _ in range(3)])
        out = associate_flow_on_a_line([v[0] for v in views], [v[1] for v in views])
        assert (out[0][20, 20] == out[7][20, 160]) == same and out[0][20, 20] > 0 and out[7][20, 160] > 0


def test_a_weak_overlap_with_another_objects_colours_is_not_a_match():
    """Between views 2 and 3 the blue box jumps onto a corner of where the red one was (IoU
    0.18, over the second round's 0.1) and the red one far away. Both colours have the grey
    level of the background, so the optical flow (on grey levels) carries nothing; the
    colours keep each box's ID."""
    red, blue = (255, 80, 42), (60, 138, 255)  # grey level 128, as the background

    def view(red_x: int, blue_x: int) -> tuple[np.ndarray, np.ndarray]:
        seg, image = np.zeros((40, 200), np.int32), np.full((40, 200, 3), 128, np.uint8)
        for label, x, color in ((1, red_x, red), (2, blue_x, blue)):
            seg[10:30, x:x + 20], image[10:30, x:x + 20] = label, color
        return image, seg

    views = [view(10, 100) for _ in range(3)] + [view(160, 24) for _ in range(3)]
    out = associate_flow_on_a_line([v[0] for v in views], [v[1] for v in views])
    assert out[0][20, 20] == out[5][20, 170] > 0  # red
    assert out[0][20, 110] == out[5][20, 34] > 0  # blue
    assert out[0][20, 20] != out[0][20, 110]


def test_the_path_through_the_views_depends_on_the_poses_alone():
    """A 12-view orbit given in a shuffled order: the path visits the same poses in the same
    order, and every step goes to a neighbour on the circle."""
    angles = 2 * np.pi * np.arange(12) / 12 + 0.01 * np.sin(np.arange(12))  # uneven: no exact ties
    centers = np.stack([np.cos(angles), np.sin(angles), np.zeros(12)], 1)
    directions = -centers
    path = pose_order(centers, directions)
    assert sorted(path) == list(range(12))
    assert all(abs(a - b) % 12 in (1, 11) for a, b in zip(path, path[1:]))
    shuffle = np.random.default_rng(0).permutation(12)
    shuffled = pose_order(centers[shuffle], directions[shuffle])
    assert [int(shuffle[k]) for k in shuffled] == path
