"""What a finished run writes, from its trained state: renders, exposure-ratio and motion-ratio
corrections, colour anchor, video, trajectory and PLY."""
