"""Every effect and every built-in look over OpenEXR's unusual-value test images (issue 10)."""
