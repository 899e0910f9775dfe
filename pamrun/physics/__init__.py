"""The robot and its muscles: body, pneumatic muscles, valve, air, hysteresis, and their coupling to the joints."""
