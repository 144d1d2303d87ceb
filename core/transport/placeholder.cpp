// Replaced as soon as the first real transport source lands.
namespace cloudbake { int cloudbake_transport_placeholder = 0; }
