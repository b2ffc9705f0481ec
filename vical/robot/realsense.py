"""An Intel RealSense D435i or D455 as a ``ViSensor``, through pyrealsense2 (``pip install 'vical[realsense]'``).

A thin adapter, written against pyrealsense2's documented API and not run on a camera in this
project: it configures the streams, converts frames and stamps, and pairs the two IMU streams;
nothing more. Check a short recording before a collection.

Streams. The camera is the left infrared imager (8-bit grey, the emitter's dot pattern switched off
by default) or the colour imager (converted to grey). The gyroscope and the accelerometer are two
streams at different rates; each gyro sample becomes one IMU sample, with the accelerometer linearly
interpolated to its stamp (``ImuPairer``), so the IMU rate is the gyro rate.

Clocks. Every frame carries a stamp in milliseconds and the domain it was measured in:

- ``global_time=False`` (the default): both streams keep the device's hardware clock
  (``hardware_clock`` domain), so the camera-IMU offset is small and constant; the camera's stamps
  need the frame metadata (the RealSense kernel patch or the RSUSB backend), otherwise they fall back
  to the host's arrival time (``system_time``), which ``read`` refuses as a different clock.
- ``global_time=True``: the device converts its hardware clock to the host clock by tracking their
  difference (``global_time`` domain): both streams then share the host's clock, with the tracking's
  jitter in it.

Stamps are converted to integer nanoseconds (``ns_from_ms``).
"""

from __future__ import annotations

from collections import deque
from typing import Any

import cv2
import numpy as np

from vical.data import ImuSamples
from vical.robot.interfaces import CameraImage, SensorData, SensorStreamError, ViSensor

INSTALL_HINT = "RealSenseSensor needs the pyrealsense2 package: pip install 'vical[realsense]'"
STREAMS = ("infrared", "color")


def ns_from_ms(t_ms: float) -> int:
    """Integer nanoseconds of a RealSense stamp in milliseconds.

    Rounded to the microsecond first: the device clock ticks in microseconds, and ``t_ms * 1e6`` of a
    host-clock stamp (~1.7e12 ms) exceeds what a float holds exactly.
    """
    return round(t_ms * 1000.0) * 1000


class ImuPairer:
    """Pairs the accelerometer with the gyroscope: one IMU sample per gyro stamp, accel interpolated linearly.

    Gyro samples wait until an accelerometer sample at or after their stamp arrived; those before the
    first accelerometer sample are dropped (they cannot be interpolated). The two streams may arrive
    in any order relative to each other; stamps are int ns and must increase strictly within each
    stream (``SensorStreamError`` otherwise).
    """

    def __init__(self) -> None:
        self._gyro_t: list[int] = []
        self._gyro: list[np.ndarray] = []
        self._accel_t: list[int] = []
        self._accel: list[np.ndarray] = []
        self._last = {"gyroscope": None, "accelerometer": None}  # the latest stamp [ns] of each stream

    def add_gyro(self, t_ns: int, rate: np.ndarray) -> None:
        """A gyro sample: ``rate`` (3,) [rad/s] at ``t_ns``."""
        self._check_increasing("gyroscope", t_ns)
        self._gyro_t.append(int(t_ns))
        self._gyro.append(np.asarray(rate, dtype=float))

    def add_accel(self, t_ns: int, specific_force: np.ndarray) -> None:
        """An accelerometer sample: ``specific_force`` (3,) [m/s^2] at ``t_ns``."""
        self._check_increasing("accelerometer", t_ns)
        self._accel_t.append(int(t_ns))
        self._accel.append(np.asarray(specific_force, dtype=float))

    def _check_increasing(self, stream: str, t_ns: int) -> None:
        last = self._last[stream]
        if last is not None and t_ns <= last:
            raise SensorStreamError(f"the {stream} stamps went backwards: {t_ns} ns after {last} ns")
        self._last[stream] = int(t_ns)

    def pop(self) -> ImuSamples:
        """The IMU samples that can be formed now, in stamp order; the rest waits for more accelerometer data."""
        if not self._accel_t or not self._gyro_t:
            return ImuSamples.concatenate([])
        gyro_t, accel_t = np.array(self._gyro_t, np.int64), np.array(self._accel_t, np.int64)
        ready = (gyro_t >= accel_t[0]) & (gyro_t <= accel_t[-1])
        waiting = gyro_t > accel_t[-1]
        t0 = accel_t[0]  # interpolate in offsets from t0: absolute ns stamps lose precision as floats
        accel = np.stack(self._accel)
        x = (gyro_t[ready] - t0).astype(float)
        xp = (accel_t - t0).astype(float)
        paired = np.column_stack([np.interp(x, xp, accel[:, k]) for k in range(3)])
        samples = ImuSamples(gyro_t[ready], np.stack(self._gyro)[ready], paired)
        self._gyro_t = [t for t, w in zip(self._gyro_t, waiting, strict=True) if w]
        self._gyro = [g for g, w in zip(self._gyro, waiting, strict=True) if w]
        if ready.any():
            # Gyro samples still to come lie after the last one delivered: keep the accelerometer samples
            # from the one at or before it, so that a gyro sample arriving late is still bracketed.
            keep = int(np.searchsorted(accel_t, gyro_t[ready][-1], side="right")) - 1
            self._accel_t, self._accel = self._accel_t[keep:], self._accel[keep:]
        return samples


def grey_image(pixels: np.ndarray, stream: str) -> np.ndarray:
    """The 8-bit grey (H, W) image of an infrared (y8) or colour (bgr8) frame's pixels."""
    if stream == "infrared":
        return np.ascontiguousarray(pixels, dtype=np.uint8)
    return cv2.cvtColor(np.ascontiguousarray(pixels, dtype=np.uint8), cv2.COLOR_BGR2GRAY)


class RealSenseSensor(ViSensor):
    """A D435i / D455's imager and IMU (module doc: streams and clocks).

    Args:
        stream: ``"infrared"`` (the left imager, global shutter on the D435i and D455) or ``"color"``.
        width, height: [px] the image size (a mode the device offers for ``stream``).
        fps: [Hz] the camera rate.
        gyro_hz, accel_hz: [Hz] the gyroscope and accelerometer rates (D435i / D455: 200 or 400, 63 or 250).
        global_time: stamp in the host clock (True) or the device's hardware clock (False).
        emitter: keep the infrared projector on (its dot pattern disturbs corner detection).
        exposure_us: [us] a fixed exposure of the imager; None keeps auto exposure.
        serial: the device's serial number; None takes the first device found.
    """

    def __init__(
        self,
        stream: str = "infrared",
        width: int = 640,
        height: int = 480,
        fps: int = 30,
        gyro_hz: int = 200,
        accel_hz: int = 250,
        global_time: bool = False,
        emitter: bool = False,
        exposure_us: float | None = None,
        serial: str | None = None,
    ) -> None:
        try:
            import pyrealsense2 as rs
        except ImportError as err:
            raise ImportError(INSTALL_HINT) from err
        if stream not in STREAMS:
            raise ValueError(f"stream must be one of {STREAMS}, got {stream!r}")
        self._rs = rs
        self._stream = stream
        self.image_size = (int(width), int(height))
        self.camera_rate_hz = float(fps)
        self.imu_rate_hz = float(gyro_hz)
        self._pipeline = rs.pipeline()
        self._config = self._stream_config(serial, fps, gyro_hz, accel_hz)
        device = self._config.resolve(rs.pipeline_wrapper(self._pipeline)).get_device()
        # Pin the resolved device, so that the options set below are those of the device that streams.
        self._config.enable_device(device.get_info(rs.camera_info.serial_number))
        self._set_options(device, global_time, emitter, exposure_us)
        self._inbox: deque[tuple[str, float, Any, Any]] = deque()  # appended by librealsense's thread
        self._streaming = False
        self._reset_streams()

    def _stream_config(self, serial: str | None, fps: int, gyro_hz: int, accel_hz: int) -> Any:
        rs = self._rs
        config = rs.config()
        if serial is not None:
            config.enable_device(str(serial))
        width, height = self.image_size
        if self._stream == "infrared":
            config.enable_stream(rs.stream.infrared, 1, width, height, rs.format.y8, int(fps))
        else:
            config.enable_stream(rs.stream.color, width, height, rs.format.bgr8, int(fps))
        config.enable_stream(rs.stream.gyro, rs.format.motion_xyz32f, int(gyro_hz))
        config.enable_stream(rs.stream.accel, rs.format.motion_xyz32f, int(accel_hz))
        return config

    def _set_options(self, device: Any, global_time: bool, emitter: bool, exposure_us: float | None) -> None:
        rs = self._rs
        for sensor in device.query_sensors():
            if sensor.supports(rs.option.global_time_enabled):
                sensor.set_option(rs.option.global_time_enabled, float(global_time))
        imager = device.first_depth_sensor() if self._stream == "infrared" else device.first_color_sensor()
        if self._stream == "infrared" and imager.supports(rs.option.emitter_enabled):
            imager.set_option(rs.option.emitter_enabled, float(emitter))
        if exposure_us is not None:
            imager.set_option(rs.option.enable_auto_exposure, 0.0)
            imager.set_option(rs.option.exposure, float(exposure_us))

    def _reset_streams(self) -> None:
        self._inbox.clear()
        self._imu = ImuPairer()
        self._domains: dict[str, Any] = {}
        self._last_frame_ns: int | None = None

    def start(self) -> None:
        self._reset_streams()
        self._pipeline.start(self._config, self._on_frame)
        self._streaming = True

    def _on_frame(self, frame: Any) -> None:
        """librealsense's callback (its own thread): copy each frame's data out and queue it for ``read``.

        Copying at once returns the frame to librealsense's pool; checks and conversions that may raise
        run in ``read``, since an exception here would be lost in the library's thread.
        """
        if frame.is_frameset():
            for inner in frame.as_frameset():
                self._on_frame(inner)
            return
        rs = self._rs
        kind = frame.get_profile().stream_type()
        if kind in (rs.stream.gyro, rs.stream.accel):
            v = frame.as_motion_frame().get_motion_data()
            data: Any = (v.x, v.y, v.z)
            name = "gyro" if kind == rs.stream.gyro else "accel"
        else:
            data = np.array(frame.as_video_frame().get_data(), copy=True)
            name = "image"
        self._inbox.append((name, frame.get_timestamp(), frame.get_frame_timestamp_domain(), data))

    def read(self) -> SensorData:
        if not self._streaming:
            return SensorData.empty()
        frames = []
        while self._inbox:
            name, t_ms, domain, data = self._inbox.popleft()
            self._check_clock(name, domain)
            t_ns = ns_from_ms(t_ms)
            if name == "gyro":
                self._imu.add_gyro(t_ns, np.array(data))
            elif name == "accel":
                self._imu.add_accel(t_ns, np.array(data))
            else:
                frames.append(self._camera_image(t_ns, data))
        return SensorData(frames, self._imu.pop())

    def _check_clock(self, name: str, domain: Any) -> None:
        """Every stream must be stamped in the same clock domain, and each keep its domain."""
        self._domains.setdefault(name, domain)
        if len({str(d) for d in self._domains.values()}) > 1 or self._domains[name] != domain:
            raise SensorStreamError(
                f"the RealSense streams are stamped in different clocks ({self._domains}, now {name} in {domain}): "
                "the camera's hardware stamps need the frame metadata (the RealSense kernel patch or the RSUSB "
                "backend), or set global_time=true"
            )

    def _camera_image(self, t_ns: int, pixels: np.ndarray) -> CameraImage:
        if self._last_frame_ns is not None and t_ns <= self._last_frame_ns:
            raise SensorStreamError(f"the camera stamps went backwards: {t_ns} ns after {self._last_frame_ns} ns")
        self._last_frame_ns = t_ns
        return CameraImage(t_ns, grey_image(pixels, self._stream))

    def stop(self) -> None:
        if self._streaming:
            self._streaming = False
            self._pipeline.stop()

    def close(self) -> None:
        """Nothing beyond ``stop``: librealsense releases the device with the stopped pipeline."""
        self.stop()
