"""Every speed figure of the project in one place; `woody bench sim|vision|graph` runs them (:mod:`.suite`).

- :mod:`.physics`: the physics alone (ms per step, real-time factor) with N fillets on the line;
- :mod:`.rendering`: our renderer against pybullet's TinyRenderer (:mod:`.tiny_renderer`) on the same scene;
- :mod:`.vision`: the per-frame cost of the segmenter and grader work, without ROS;
- :mod:`.verdict_latency`: the real vision nodes, frame-in to verdict-out;
- :mod:`.recorder`: the recorder's throughput on camera-sized streams (`python -m woody_tools.benchmarks.recorder`).
"""
