"""The fingertip force board: three HX711 load-cell ADCs on an Arduino Nano, streaming the frames that
`robots/blindgrasp_gripper/force_sensor.py` reads. Parts, wiring, flashing and the protocol: docs/force_board.md.

    firmware/force_board.c, firmware/Makefile    the firmware (plain avr-libc) and its build
    simavr/hx711_sim.c                           the board in simavr: the firmware's HEX image, emulated HX711
                                                 chips on its pins, its UART on a pseudo-terminal
    build.py                                     `build_firmware(out_dir)`, `build_simulator(out_dir)`, and the
                                                 command `python -m lerobot_blindgrasp.hardware.force_board.build`
    (the board in simavr as a device for the tests and the twin: `emulators/force_board_simavr.py`)
"""
