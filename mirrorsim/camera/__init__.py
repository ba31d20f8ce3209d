"""The camera's sensor and lens model (sRGB coding, noise, radial distortion): what the
renderer applies to a frame and the detector undoes, in a wing below both."""
