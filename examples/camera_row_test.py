"""Camera row selection test: port of the thesis's Fig. 5.2.

Run it:  simrunner drive examples/camera_row_test.py --video rows.mp4

The car stands still; every image row 0..127 is taken in turn and labelled in the debug
video ("image_row:i" in the text column, the row stretched beside the camera image), so the
video shows which row sees a given mark (the thesis put the car the desired distance
before the finish line and read off row 60). Place the car with ``--track`` (the start pose
of the track).

The C++ original::

    Spinner s;
    for (int i = 0; i < 128; i++) {
        s.addData({"image_row:" + std::to_string(i)});
        s.getImage(i);
        usleep(100000);
    }
"""


def main(s):
    rows = s.image_shape[0]
    for i in range(rows):
        s.addData(["image_row:" + str(i)])
        s.getImage(i)
        s.sleep(0.1)  # usleep(100000)
