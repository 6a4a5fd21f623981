"""The order tiles are sent to workers in, and the order their results come back in."""

from engine.progress import no_progress
from engine.tile_runners import _windowed, send_order


class _Finished:
    def __init__(self, value):
        self.value = value

    def result(self):
        return self.value


def test_costliest_tiles_go_first():
    assert send_order(5, [3.0, 9.0, 1.0, 9.0, 5.0]) == [1, 3, 4, 0, 2]
    assert send_order(3) == [0, 1, 2]


def test_results_keep_the_tile_order_whatever_the_sending_order():
    sent = []

    def submit(args):
        sent.append(args[0])
        return _Finished(f"tile {args[0]}")

    order = send_order(4, [1.0, 4.0, 2.0, 3.0])
    results = _windowed(submit, lambda futures: futures[:1], order, lambda number: (number,),
                        window=2, progress=no_progress, cancel=None, where="here")
    assert sent == [1, 3, 2, 0]
    assert results == ["tile 0", "tile 1", "tile 2", "tile 3"]
