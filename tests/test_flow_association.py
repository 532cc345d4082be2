"""The matching rules of the ``flow`` association on hand-made sequences, and the order in
which it visits the views. The images are uniform, so the optical flow is zero and the rules
alone decide; the cameras stand on a line in the order of the list."""

import numpy as np

from dataset_tools.cameras import CameraPose, PinholeCamera
from dataset_tools.synth.camera_paths import orbit
from hqmask.association.flow import FlowOptions, _join_by_anchors, associate_flow, pose_order


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
        views = (
            [view({1: ((10, 30, 10, 30), red)}) for _ in range(3)]
            + [view({}) for _ in range(2)]
            + [view({1: ((10, 30, 150, 170), color)}) for _ in range(3)]
        )
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
            seg[10:30, x : x + 20], image[10:30, x : x + 20] = label, color
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


def handed_over(first: range, second: range, gap: int = 0) -> list[np.ndarray]:
    """One object (a disc at the centre of every view of a 12-view orbit around it) given as
    track 0 in the views ``first`` and track 1 in the views ``second``; where both are seen,
    the disc is split into a left piece (track 0) and a right piece (track 1), ``gap`` pixels
    apart. Returns, per view, the track of each local segment after :func:`_join_by_anchors`."""
    camera = PinholeCamera(64, 64, 60.0, 60.0, 32.0, 32.0)
    views = [CameraPose(camera, pose) for pose in orbit(12, 4.0, np.zeros(3))]
    rows, cols = np.indices((64, 64))
    disc = (rows - 31.5) ** 2 + (cols - 31.5) ** 2 <= 8**2
    segments, tracks_of = [], []
    for v in range(12):
        if v in first and v in second:
            segments.append(np.where(disc & (cols < 32), 1, np.where(disc & (cols >= 32 + gap), 2, 0)))
            tracks_of.append(np.array([-1, 0, 1]))
        else:
            segments.append(disc.astype(np.int32))
            tracks_of.append(np.array([-1, 0 if v in first else 1]))
    images = [np.full((64, 64, 3), 128, np.uint8) for _ in range(12)]
    return _join_by_anchors(tracks_of, segments, images, views, FlowOptions())


def test_a_track_handed_over_at_a_split_is_joined_to_the_one_before():
    """Track 0 in views 0-6, track 1 in views 5-11, two touching pieces of the disc in views 5
    and 6 (where the propagation went on with the new piece's ID): one object."""
    joined = handed_over(range(0, 7), range(5, 12))
    assert {int(t) for g in joined for t in g[1:]} == {0}


def test_tracks_seen_apart_in_most_of_their_views_stay_apart():
    """Views 3-6 show the two tracks apart, more than the 3 views track 0 has alone: two
    objects side by side, however close their anchors."""
    joined = handed_over(range(0, 7), range(3, 12))
    assert {int(t) for g in joined for t in g[1:]} == {0, 1}


def test_pieces_that_do_not_touch_are_not_a_split_mask():
    joined = handed_over(range(0, 7), range(5, 12), gap=3)
    assert {int(t) for g in joined for t in g[1:]} == {0, 1}
