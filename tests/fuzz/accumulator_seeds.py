#!/usr/bin/env python3
# Writes the extended-format ("acc2") seeds of fuzz_accumulator.cpp into a folder:
#
#   python3 tests/fuzz/accumulator_seeds.py tests/fuzz/corpus/accumulator
#
# FuzzedDataProvider takes its integers from the end of the data, a value in [lo, hi] from as
# many bytes as hi - lo needs (most significant first) modulo hi - lo + 1; so the values are
# listed here in the order the target takes them and written reversed after the tag. Each
# seed follows the target's calls; change both together.
import os
import sys

# The values an input gives, in the order the target takes them.
class Enc:
    def __init__(self): self.taken = []
    def rng(self, lo, hi, v):
        assert lo <= v <= hi, (lo, hi, v)
        r, n = hi - lo, 0
        while n < 64 and (r >> n) > 0: n += 8
        n //= 8
        x = v - lo
        self.taken += [(x >> (8 * (n - 1 - i))) & 0xff for i in range(n)]
    def boolean(self, b): self.rng(0, 255, 1 if b else 0)
    def data(self): return b'acc2' + bytes(reversed(self.taken))

def sample(e, v):  # an ordinary sample: v in [0, 20] to 0.01
    e.rng(0, 3, 1); e.rng(0, 2000, int(round(v * 100)))

# A frame's reset (valid), then its calls (the op numbers of LLVMFuzzerTestOneInput's switch).
class Frame:
    def __init__(self, e, w, h, k, nc):
        self.e, self.w, self.h, self.k, self.nc = e, w, h, k, nc
        e.rng(1, 8, w); e.rng(1, 8, h)
        if k <= 17: e.rng(0, 7, 1); e.rng(2, 17, k)
        else: e.rng(0, 7, 0); e.rng(18, 64, k)
        e.rng(1, 4, nc); e.rng(0, 15, 15)  # (15: not a refused reset)
    def op(self, o): self.e.rng(0, 27, o)
    def layout(self, layout, pad):
        self.e.rng(0, 4, layout)
        if layout: self.e.rng(1, 3, pad)
    def flat_pass(self, colour, layout=0, pad=1):  # colour: nc values, or None: black
        self.op(23); self.layout(layout, pad)
        if colour is None: self.e.rng(0, 7, 7); return
        self.e.rng(0, 7, 6)
        for v in colour: sample(self.e, v)
    def pass_values(self, values, layout=0, pad=1):  # w * h * nc values
        self.op(23); self.layout(layout, pad); self.e.rng(0, 7, 0)
        for v in values: sample(self.e, v)
    def tile(self, double, tw, th, x0, y0, index, values, layout=0, pad=1):
        self.op(3 if double else 1)
        e = self.e
        e.rng(1, self.w + 1, tw); e.rng(1, self.h + 1, th); e.rng(-1, self.w, x0); e.rng(-1, self.h, y0)
        e.rng(0, 7, 1)  # the frame's channels
        e.rng(0, 7, 1); e.rng(0, 40, index)
        self.layout(layout, pad); e.rng(0, 7, 0)
        for v in values: sample(e, v)
    def add(self, x, y, index, values):
        self.op(4)
        e = self.e
        e.rng(-1, self.w, x); e.rng(-1, self.h, y); e.rng(0, 7, 1); e.rng(0, 40, index)
        for v in values: sample(e, v)
        e.rng(0, 15, 1)
    def finish(self): self.op(20)
    def process(self, use_variance): self.op(21); self.e.boolean(use_variance)
    def move(self): self.op(22)

def shade(i, j=0): return 1.0 + ((i * 7 + j * 3) % 11) / 50.0

def write(name, e, calls_end):
    calls_end()
    with open(os.path.join(sys.argv[1], name), 'wb') as f: f.write(e.data())

# K = 17 on 3 x 3: a pass per buffer (all 17 usable: sorted by std::sort), a firefly in one
# buffer at the centre, a process round, more samples, the end.
e = Enc(); f = Frame(e, 3, 3, 17, 1); e.rng(0, 400, 21)  # calls
for b in range(17): f.flat_pass([shade(b)])
f.add(1, 1, 5, [19.5])
f.process(False)
f.add(0, 0, 17 + 3, [1.1])
f.add(2, 1, 17 + 8, [1.2])
def end_k17(): e.boolean(False); e.boolean(True)
write('acc2-k17-passes-firefly', e, end_k17)

# K = 9 on 4 x 4, 3 channels: buffer 4 black everywhere, the others lit (a dropped buffer in
# the 64-bit masks), then finish and process with the spread.
e = Enc(); f = Frame(e, 4, 4, 9, 3); e.rng(0, 400, 10)  # calls
for b in range(9): f.flat_pass(None if b == 4 else [shade(b), shade(b, 1), shade(b, 2)])
f.finish()
def end_k9(): e.boolean(False); e.boolean(False)
write('acc2-k9-dropped-buffer', e, end_k9)

# K = 64 on 2 x 1: a pass per buffer, one black (the all-ones mask of 64 buffers), variance on.
e = Enc(); f = Frame(e, 2, 1, 64, 1); e.rng(0, 400, 64)  # calls
for b in range(64): f.flat_pass(None if b == 9 else [shade(b)])
def end_k64(): e.boolean(False); e.boolean(True)
write('acc2-k64-passes', e, end_k64)

# K = 3 on 2 x 2, 2 channels: tiles in every layout (packed, padded rows, padded pixels,
# planar, bottom-up; float and double), finish twice, process between adds, moved out and back,
# then a reset to K = 4 on 2 x 1 and passes laid out bottom-up and planar.
e = Enc(); f = Frame(e, 2, 2, 3, 2); e.rng(0, 400, 16)  # calls
vals = lambda seed: [shade(seed, i) for i in range(2 * 2 * 2)]
for index, (double, layout) in enumerate([(False, 0), (False, 1), (True, 2), (False, 3), (True, 4), (False, 2)]):
    f.tile(double, 2, 2, 0, 0, index, vals(index), layout, 1 + index % 3)
f.finish()
f.add(1, 1, 7, [12.0, 9.0])
f.process(True)
f.move()
f.finish()
f.op(0); g = Frame(e, 2, 1, 4, 2)
for b in range(4): g.pass_values([shade(b, i) for i in range(4)], layout=4 if b % 2 else 3, pad=2)
def end_strided(): e.boolean(True); e.boolean(False)
write('acc2-strided-tiles-and-rounds', e, end_strided)
