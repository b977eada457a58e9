"""Camera row selection test: port of the thesis's Fig. 5.2.

Run it:  simrunner drive examples/camera_row_test.py --start-before-finish 0.30 --video rows.mp4

The car stands still; every image row 0..127 is taken in turn and labelled in the debug
video ("image_row:i" in the text column, the row stretched beside the camera image), so the
video shows which row sees a given mark. As in the thesis, ``--start-before-finish D`` puts
the car's front bumper D metres before the finish line (the distance the camera should look
ahead); the row that sees the line is the one to use (the thesis read off row 60).
``--start X,Y,YAW`` places the car anywhere else.

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
