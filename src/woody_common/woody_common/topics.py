"""Topic names that more than one woody package publishes or subscribes (relative names, REP 135), and the names
of the line's frames on ``tf_static``.

A namespace (``--ros-args -r __ns:=/line2``) moves the topics all together.
"""

GROUND_TRUTH = "line/ground_truth"
TOP_COLOR_IMAGE = "top_camera/color/image_raw"
TOP_DEPTH_IMAGE = "top_camera/depth/image_raw"
TOP_DEPTH_INFO = "top_camera/depth/camera_info"
SIDE_IMAGE = "side_camera/image_raw"
TRACKS = "vision/tracks"
VERDICTS = "grading/verdicts"
SIDE_METRICS = "grading/side_metrics"
ANNOTATIONS = "grading/annotations"
"""One foxglove_msgs/ImageAnnotations per top frame: the grader's outlines and labels (woody_vision.annotations)."""
GATE_COMMANDS = "reject_gate/commands"
DIAGNOSTICS = "diagnostics"
"""Every node's health once a second (woody_common.diagnostics)."""
RECORDED_CLOCK = "recorder/recorded_clock"
"""The newest /clock stamp the recorder has written: line_sim holds while it lags (back-pressure on the line)."""

TRACKS_QUEUE_DEPTH = 900
"""History of the reliable /vision/tracks link at both ends: 30 s of a 30 Hz camera. Track messages are
small and a verdict needs a track's first frames, so a grader held up (a loaded machine, a replay that
does not wait for it) must catch up from the queue instead of losing the oldest frames."""
TF_STATIC = "tf_static"
"""The line's fixed frames (tf2_msgs/TFMessage, latched)."""

WORLD_FRAME = "world"
"""REP 103: x downstream along the flow, z up, the origin on the belt surface at the roller edge, mid-belt."""
ROLLER_FRAME = "roller"
"""The end roller's axle (x along the flow, as the world frame)."""
TOP_FRAME = "top_camera_optical_frame"
SIDE_FRAME = "side_camera_optical_frame"
"""Optical frames (REP 103): z along the optical axis, x right and y down in the image."""
