"""The ``viewer`` node: the arm, live, in a window -- or headless, as a PNG file.

Subscribes ``joint_states``, ``arm_state``, ``planned_path``, ``cspace_map``, ``goal_point``
and (when the controller publishes it) ``controller/setpoint``; draws them with
``arm_control.visual.scene``. In a window a left click on the workspace publishes a
``goal_point`` in ``arm_base`` and a ghost follows the mouse. With ``headless:=true``, or with
no display, it writes the picture to ``png_path`` ``png_rate_hz`` times a second instead.
"""

import os
import sys

from geometry_msgs.msg import PointStamped
from nav_msgs.msg import OccupancyGrid
from rclpy.node import Node

from arm_control.config import ArmConfig, FRAME_ID
from arm_control.nodes.common import COMMANDS, declare_parameters, LATCHED, run
from arm_control.nodes.view_inputs import ViewInputs
from arm_control.visual.scene import cspace_from_occupancy, workspace_extent
from arm_control.visual.scene_view import SceneView
from arm_control.visual.viewer_model import ViewerConfig, ViewerModel


def have_display() -> bool:
    return bool(os.environ.get('DISPLAY') or os.environ.get('WAYLAND_DISPLAY'))


class ViewerNode(Node):

    def __init__(self):
        super().__init__('viewer')
        params = declare_parameters(self, 'viewer')
        self.arm = ArmConfig.from_parameters(params)
        self.config = ViewerConfig.from_parameters(params)
        self.model = ViewerModel(self.arm, self.config.goal_reached_m)
        self.window_closed = False

        figure = None
        self.headless = self.config.headless or not have_display()
        if not self.headless:
            try:
                figure = self._open_window()
            except Exception as error:           # no Tk, display refused: still useful headless
                self.get_logger().warning(f'cannot open a window ({error}): rendering to '
                                          f'{self.config.png_path} instead')
                self.headless = True
        self.view = SceneView(self.arm, figure=figure)

        self.goal_pub = self.create_publisher(PointStamped, 'goal_point', COMMANDS)
        self.inputs = ViewInputs(self, self.model)
        self.create_subscription(OccupancyGrid, 'cspace_map', self.on_cspace_map, LATCHED)

        if self.headless:
            self.create_timer(1.0 / self.config.png_rate_hz, self.write_png)
            why = '' if self.config.headless or have_display() else ' (no DISPLAY)'
            self.get_logger().info(f'headless{why}: writing {self.config.png_path} '
                                   f'{self.config.png_rate_hz:g} times a second')
        else:
            self.view.start_live()
            canvas = self.view.figure.canvas
            canvas.mpl_connect('motion_notify_event', self.on_mouse_move)
            canvas.mpl_connect('axes_leave_event', self.on_mouse_leave)
            canvas.mpl_connect('button_press_event', self.on_click)
            canvas.mpl_connect('close_event', self.on_window_closed)
            self.create_timer(1.0 / self.config.rate_hz, self.refresh_window)
            self.get_logger().info('viewer window open: click to send a goal_point')

    def _open_window(self):
        import matplotlib
        matplotlib.use('TkAgg')
        matplotlib.rcParams['toolbar'] = 'None'    # a click means a goal, never pan or zoom
        from matplotlib import pyplot
        width_px, height_px = SceneView.natural_size_px(workspace_extent(self.arm))
        figure = pyplot.figure('arm_control viewer', figsize=(width_px / 100, height_px / 100),
                               dpi=100)
        pyplot.show(block=False)
        return figure

    # -- messages in ---------------------------------------------------------------------

    def on_cspace_map(self, msg: OccupancyGrid) -> None:
        info = msg.info
        try:
            image = cspace_from_occupancy(info.width, info.height, info.resolution,
                                          info.origin.position.x, info.origin.position.y,
                                          msg.data)
        except ValueError as error:
            self.get_logger().warning(f'cspace_map ignored: {error}', throttle_duration_sec=5.0)
            return
        self.view.set_cspace(image)

    # -- the window ----------------------------------------------------------------------

    def on_mouse_move(self, event) -> None:
        self.model.ghost_xy = self.view.workspace_point(event)

    def on_mouse_leave(self, event) -> None:
        self.model.ghost_xy = None

    def on_click(self, event) -> None:
        point = self.view.workspace_point(event)
        if point is None or event.button != 1:
            return
        msg = PointStamped()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = FRAME_ID
        msg.point.x, msg.point.y = point
        self.goal_pub.publish(msg)
        self.get_logger().info(f'goal_point ({point[0]:.3f}, {point[1]:.3f}) m published')

    def on_window_closed(self, event) -> None:
        self.window_closed = True

    def refresh_window(self) -> None:
        if self.window_closed:
            self.get_logger().info('window closed: stopping')
            self.context.try_shutdown()         # rclpy.spin returns; run() cleans up
            return
        self.view.draw_live(self.model.scene(self.inputs.now_s()))
        self.view.figure.canvas.flush_events()

    def write_png(self) -> None:
        path = self.config.png_path
        partial = f'{path}.part'
        try:
            self.view.render_png(self.model.scene(self.inputs.now_s()), partial)
            os.replace(partial, path)          # readers never see half a picture
        except OSError as error:
            self.get_logger().error(f'cannot write {path}: {error}', throttle_duration_sec=10.0)

    def on_shutdown(self) -> None:
        if self.headless:
            self.write_png()                    # the picture of where the arm ended
        else:
            from matplotlib import pyplot
            pyplot.close('all')


def main(args=None):
    sys.exit(run(ViewerNode, args))


if __name__ == '__main__':
    main()
