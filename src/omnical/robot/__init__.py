"""Robot descriptions: wheels, limits, drive train, IMU, hedgehog mounting; presets and YAML loading."""
