"""The hardware, one home per device: what the simulation and the real gripper share about it, and how the host
talks to it. The XM430 servo's facts (`xm430`) and the Dynamixel bus (`dynamixel/`: retries, latency timer); the
fingertip load cell's signal chain (`force`) and the force board (`force_board/`: firmware, frames, reader,
calibration); what every serial device shares (`ports`: one owner per port; `streams`: the newest frame of a
streaming device, kept by a thread); and what the host process needs to keep a control loop's time (`realtime`: a
real-time priority, locked memory, no GC in a trial). `sim/` models these and `robots/` drives them; nothing here
imports MuJoCo."""
