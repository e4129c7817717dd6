"""Rendering a bike folder in Blender: the 36-view ring of each part (render_views), a posed bike
from a camera (render_pose), the shared render settings (render) and the albedo/normal passes."""
