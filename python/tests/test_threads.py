"""The GIL is released while a frame is processed, so Python threads with a detector each run
in parallel; their results equal the serial ones. No timing: the release is shown by the
order of events under a switch interval so long that a thread holding the GIL is never
interrupted."""
import threading

import numpy as np

import firefly
from conftest import arrays_of, assert_gil_released, make_frame, report_as_text, same_bits


def cleaned(frame, threads=1):
    arrays = {k: v.copy() for k, v in arrays_of(frame).items()}
    rep = firefly.Detector(threads=threads).process(**arrays)
    return arrays, report_as_text(rep)


def test_gil_is_released_during_process():
    big = arrays_of(make_frame(height=1024, width=1024, seed=3))
    det = firefly.Detector()
    assert_gil_released(lambda: det.process(**big))


def test_two_threads_two_detectors_equal_the_serial_results():
    frames = [make_frame(seed=s, height=256, width=320) for s in (21, 22)]
    serial = [cleaned(f) for f in frames]
    results = [None, None]

    def run(i):
        results[i] = cleaned(frames[i], threads=2)

    threads = [threading.Thread(target=run, args=(i,)) for i in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for (arrays, report), (ref_arrays, ref_report) in zip(results, serial):
        assert report == ref_report
        for k in arrays:
            assert same_bits(arrays[k], ref_arrays[k]), k


def test_one_detector_shared_by_threads_is_serialized():
    det = firefly.Detector()
    frames = [arrays_of(make_frame(seed=s)) for s in range(31, 35)]
    reference = [cleaned(f)[0] for f in frames]
    copies = [{k: v.copy() for k, v in f.items()} for f in frames]
    errors = []

    def run(i):
        try:
            det.process(**copies[i])
        except Exception as e:  # reported below; a thread's exception is otherwise lost
            errors.append(e)

    threads = [threading.Thread(target=run, args=(i,)) for i in range(len(frames))]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors
    for got, ref in zip(copies, reference):
        for k in got:
            assert same_bits(got[k], ref[k]), k


def test_thread_count_does_not_change_the_bits():
    frame = make_frame(seed=5)
    one, rep_one = cleaned(frame, threads=1)
    two, rep_two = cleaned(frame, threads=2)
    assert rep_one == rep_two
    assert all(same_bits(one[k], two[k]) for k in one)
    assert np.isfinite(one["b_color"]).all()  # the NaN pixel was repaired
