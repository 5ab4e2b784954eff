"""Dr.Jit 1.5 (LLVM): with JitFlag.Debug on and more than one thread, a packet
scatter-reduction in the (default) expanded mode is reported out of bounds and its
writes are dropped.

    python drjit_debug_expanded_packet_scatter.py

Expected: no message; every column sums to N times its value.
Observed (Dr.Jit 1.5.0, LLVM 19, 2 threads): "drjit.scatter_reduce(): out-of-bounds
packet write to position P in an array of size S" with S <= P < threads * S, and
wrong sums. The same reduction without Debug, with one thread, or with 3 values a
packet (not a packet op) is right.
"""

import drjit as dr
from drjit.llvm import Array4f, Float, UInt32

dr.set_thread_count(2)
dr.set_flag(dr.JitFlag.Debug, True)

pixels, n = 576, 1 << 20  # a 32x18 film of 4 channels; enough lanes for both threads
target = dr.zeros(Float, 4 * pixels)
index = dr.arange(UInt32, n) % pixels
dr.scatter_reduce(dr.ReduceOp.Add, target, Array4f(1, 2, 3, 4), index)  # ReduceMode.Auto -> Expand
sums = target.numpy().reshape(pixels, 4).sum(axis=0)
print("sums", sums.tolist(), "expected", [n * k for k in (1, 2, 3, 4)])
