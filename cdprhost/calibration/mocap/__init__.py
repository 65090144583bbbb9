"""The motion-capture source: takes recorded by a motion-capture system, read from the
exports of its software and reduced to the same observations as every source (each pose's
effector point with its standard error) that identification takes.

- :mod:`.readers`: take files (Motive, Vicon, Qualisys, C3D) read and written;
- :mod:`.registration`: the base frame registered from the base markers (Kabsch);
- :mod:`.takes`: the ``[mocap]`` table and a take -> its effector series in the base frame;
- :mod:`.setup`: a ``[mocap]`` configuration started from one take's markers.
"""
