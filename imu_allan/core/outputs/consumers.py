"""
How the consumers of the noise numbers (VIO, SLAM, robot_localization) read them.

Facts about the other packages' config readers, kept with the outputs that feed them
(:mod:`imu_allan.core.outputs.exports`).
"""

#: How VIO / SLAM packages read IMU noise numbers.
NOTES = """\
How VIO / SLAM packages read IMU noise numbers (check your version; all of them expect
the same physical quantities in different forms).

Common ground: N is the white-noise density sigma (rad/s/sqrt(Hz) = rad/sqrt(s) for a
gyro, m/s^2/sqrt(Hz) for an accelerometer) and K the bias random-walk density
(rad/s^2/sqrt(Hz), m/s^3/sqrt(Hz)), both continuous-time.  Discrete per-sample values at
rate f: sigma_d = N sqrt(f) (white), sigma_bd = K / sqrt(f) (bias step).  The
Gauss-Markov bias instability B has no slot in any of these packages: they model the
bias as a pure random walk, so B and T_B only enter through how you inflate K.

* Kalibr (imu.yaml): accelerometer_noise_density, accelerometer_random_walk,
  gyroscope_noise_density, gyroscope_random_walk, update_rate: continuous densities,
  one value for all three axes; Kalibr itself forms sigma / sqrt(dt) and sigma sqrt(dt)
  with dt = 1 / update_rate, which assumes the sensor low-pass filters at the Nyquist
  frequency (a subsampled, unfiltered output must not be scaled that way).
* OpenVINS (kalibr_imu_chain.yaml, same four keys): continuous densities; the
  propagator builds Qc = sigma_w^2 / dt for the white terms and sigma_wb^2 dt for the
  bias walks at each IMU interval (the exact forms above).  Its zero-velocity update
  multiplies the IMU noise by a separate zupt_noise_multiplier.
* ORB-SLAM3 (IMU.NoiseGyro, IMU.NoiseAcc, IMU.GyroWalk, IMU.AccWalk, IMU.Frequency):
  continuous densities; Tracking converts them with sf = sqrt(IMU.Frequency) to
  Ng sf, Na sf (white) and Ngw / sf, Naw / sf (walk), so a wrong IMU.Frequency scales
  the white and walk terms in opposite directions.
* VINS-Mono / VINS-Fusion (acc_n, gyr_n, acc_w, gyr_w): the config calls them noise
  standard deviations; the pre-integration (integration_base.h) puts acc_n^2 ... gyr_w^2
  straight into its noise matrix and maps them with dt-scaled (not sqrt(dt)) Jacobians
  in a mid-point scheme: per step the attitude gains gyr_n^2 dt^2 / 2 and the gyro
  bias gyr_w^2 dt^2, against N^2 dt and K^2 dt for the continuous model.  The same
  covariance growth therefore needs gyr_n ~ N sqrt(2 f) and gyr_w ~ K sqrt(f), i.e.
  the numbers act as per-sample values, not densities.  The shipped EuRoC example
  (acc_n 0.08, gyr_n 0.004, acc_w 4e-5, gyr_w 2e-6) differs from Kalibr's EuRoC
  densities (2.0e-3, 1.6968e-4, 3.0e-3, 1.9393e-5) by factors of 0.01 to 40.
* Inflation: Allan values come from a still, temperature-stable sensor; in motion,
  vibration, temperature changes, scale-factor and misalignment errors add error the
  model does not contain.  People therefore inflate the Allan numbers before use
  (factors of a few up to 10 or more on N, more on K), tune them on recorded runs, and
  use upper bounds where a term was not identified.  imu_allan reports the measured
  values and, for estimators whose bias is a random walk, the covering pair
  (:mod:`imu_allan.core.outputs.covering`): the white + random-walk densities whose Allan
  variance bounds the whole fitted model over a stated horizon, so the inflation of N
  and K is derived; motion effects still come on top.
* robot_localization has no bias states and takes no noise parameters: it reads each
  sensor_msgs/Imu message's covariance fields (variance N^2 f for white noise per
  axis) and clamps variances below 1e-9.
"""
