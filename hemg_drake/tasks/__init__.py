"""The paper's two tasks (cotter pin, drawing): scenes, plans and metrics."""
