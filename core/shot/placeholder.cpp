// Replaced as soon as the first real shot source lands.
namespace cloudbake { int cloudbake_shot_placeholder = 0; }
