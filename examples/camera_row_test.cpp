// Camera row selection test: the thesis's Fig. 5.2, unchanged but for its ROS lines.
//
// Run it:  simrunner drive examples/camera_row_test.cpp --video rows.mp4
//
// The car stands still; every image row 0..127 is taken in turn and labelled in the debug
// video ("image_row:i"), each shown for 0.1 s of simulated time (usleep waits in simulated
// time). Compare examples/camera_row_test.py. Removed from the thesis's figure:
//   rclcpp::init(argc, argv);   (and the ROS includes); added: #include "spinner.hpp".
#include "spinner.hpp"

int main(int argc, char* argv[]) {
    Spinner s;
    for (int i = 0; i < 128; i++) {
        s.addData({"image_row:" + std::to_string(i)});
        s.getImage(i);
        usleep(100000);
    }
    return 0;
}
