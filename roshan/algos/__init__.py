"""Learning code: networks, distributions, buffers and the PPO / TD3 / IQL / RND updates (torch only)."""
