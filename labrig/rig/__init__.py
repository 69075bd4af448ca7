"""What a rig is: the device roles and the ``Rig`` that joins them, what the amplifier and
actuator can do (limits, the ramp to 0 V, a drive's load), rig files and the installed drivers
(found through the ``labrig.drivers`` entry points)."""
