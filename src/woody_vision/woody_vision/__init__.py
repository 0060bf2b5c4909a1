"""The vision of the line: segmentation, tracking, shape score, side view and grading, and their nodes.

OpenCV runs single-threaded in every process that uses this package. Its worker threads spin (sched_yield)
after each parallel call, and on two cores beside the simulator, the other vision node and a sweep's second
worker that spinning takes CPU the others need (a sweep worker spent a tenth of its time in it); every image
here is small enough for one thread.
"""

import cv2

cv2.setNumThreads(1)
