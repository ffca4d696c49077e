"""The kinds of stream target, one declaration module each (`KIND = TargetKind(...)`, see ../spec.py), found by
`imu_emulator.live.transport`: adding a kind is a module here and its transport module beside ../base.py."""
