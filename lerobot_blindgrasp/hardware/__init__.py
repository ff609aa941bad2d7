"""What the simulation and the real gripper share about the hardware: the XM430 servo's facts (`xm430`), the
fingertip load cell's signal chain (`force`) and the force board's serial frames (`streams`); and what the host
process needs to keep a control loop's time (`realtime`: a real-time priority, locked memory, no GC in a trial).
`sim/` models these and `robots/` talks to them; neither imports MuJoCo from here."""
